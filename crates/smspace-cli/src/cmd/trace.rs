//! `smspace trace`: the kernel sets `M^i` through explored motor configurations.

use std::path::PathBuf;

use clap::Args as ClapArgs;
use smspace::io;
use smspace::kernel::{
    trace_sets, Components, SensorNoise, StepControl, TraceMethod, TraceParams, TracedSets,
};
use smspace::learn::budget::{learn_from_agent, BudgetParams};
use smspace::learn::LawParams;

use super::common::{split_params, with_table_params, AgentArgs, EnvArgs, WorkspaceArgs};
use crate::ui::Bar;

/// Arguments of `smspace trace`.
#[derive(Debug, ClapArgs)]
pub struct Args {
    #[command(flatten)]
    agent: AgentArgs,
    /// Motor configurations (M, N), as written by `smspace explore`.
    #[arg(long, value_name = "FILE")]
    motors: PathBuf,
    /// Level set to follow: kinematic (observer's pose, the paper's), sensory (the
    /// agent's own sensor readings; needs an environment) or learned (the law learned
    /// from babbling the agent within --budget sensor rows, the sets traced on it and
    /// verified against the agent).
    #[arg(long, default_value = "kinematic", value_parser = parse_method)]
    method: TraceMethod,
    /// --method learned: the sensor rows the agent may be read in all (babbling and
    /// verifying the sets).
    #[arg(long, value_name = "ROWS")]
    budget: Option<u64>,
    /// --method learned: babbling rounds (the first over the working space, the later
    /// ones around the sets traced so far).
    #[arg(long, default_value_t = BudgetParams::new(1).rounds)]
    rounds: usize,
    /// --method learned: rows read along each traced set to verify it.
    #[arg(long, default_value_t = BudgetParams::new(1).verify_points)]
    verify_points: usize,
    /// --method learned: seed of the babbling.
    #[arg(long, default_value_t = BudgetParams::new(1).seed)]
    seed: u64,
    /// A parameter of the [kernel] table that has no flag of its own (max_steps,
    /// pose_tolerance, sensor_tolerance, jacobian, piece_seed, ...), or of the
    /// [learn] table as learn.KEY (learn.first_round, learn.verify_tolerance,
    /// learn.batch), the value in TOML; repeatable.
    #[arg(long = "param", value_name = "KEY=VALUE", value_parser = super::common::parse_param)]
    params: Vec<(String, toml::Value)>,
    /// --method learned: a key of the law's parameters (as `smspace learn` takes
    /// them: method, invariants, neighbours, holdout, ...), as KEY=VALUE; repeatable.
    #[arg(long = "law", value_name = "KEY=VALUE")]
    law: Vec<String>,
    /// Points per resampled set.
    #[arg(long, default_value_t = TraceParams::default().points)]
    points: usize,
    /// Step length (radians); the initial step when adaptive.
    #[arg(long, default_value_t = TraceParams::default().step, allow_negative_numbers = true)]
    step: f64,
    /// Step control: auto (fixed for kinematic, adaptive for sensory), fixed or adaptive.
    #[arg(long, default_value = "auto", value_parser = parse_step_control)]
    step_control: StepControl,
    /// Largest adaptive step (radians); 0 lets the level set choose (0.2 for the sensory
    /// method on exact readings with secant Jacobians, 0.05 otherwise).
    #[arg(long, default_value_t = TraceParams::default().max_step, allow_negative_numbers = true)]
    max_step: f64,
    /// Loop-closure tolerance (torus distance).
    #[arg(long, default_value_t = TraceParams::default().closure_tolerance, allow_negative_numbers = true)]
    closure_tolerance: f64,
    /// Which pieces of a level set make a set: connected (the piece through the
    /// start, the paper's) or all (every piece the multi-start search finds).
    #[arg(long, default_value = "connected", value_parser = parse_components)]
    components: Components,
    /// Seeds of the multi-start search for pieces per set (0: no search, no check).
    #[arg(long, default_value_t = TraceParams::default().piece_starts)]
    piece_starts: usize,
    /// Sensory method: the standard deviation of one reading, `auto` (read every start
    /// twice: readings that differ beyond the corrector's tolerance are noisy, their
    /// noise measured at the start and the set traced on the level set of their mean)
    /// or a standard deviation in sensor units (0: exact readings). The [kernel] key
    /// sensor_sigma.
    #[arg(long, value_name = "auto|SIGMA", default_value = "auto", value_parser = parse_noise, allow_negative_numbers = true)]
    sensor_sigma: SensorNoise,
    /// The old name of --sensor-sigma: refused with the new one.
    #[arg(long = "noise", hide = true, allow_hyphen_values = true)]
    old_noise: Option<String>,
    /// Kernels of dimension k ≥ 2: the tangent step of the dense covering (radians).
    #[arg(long, default_value_t = TraceParams::default().cover_step, allow_negative_numbers = true)]
    cover_step: f64,
    #[command(flatten)]
    env: EnvArgs,
    #[command(flatten)]
    workspace: WorkspaceArgs,
    /// Output sets (M_kept, P, N); next to it `<stem>.kept.npy` (the motor row of each
    /// set), `<stem>.closed.npy` (1: closed loop, 0: open), `<stem>.components.npy`
    /// (M_kept, P: the piece of every point) and `<stem>.trace.json`.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Refuse to start when the output needs more than this many bytes (default: the
    /// memory available, MemAvailable in /proc/meminfo).
    #[arg(long, value_name = "BYTES")]
    max_memory: Option<u64>,
}

fn parse_method(s: &str) -> Result<TraceMethod, String> {
    s.parse()
}

fn parse_components(s: &str) -> Result<Components, String> {
    s.parse()
}

fn parse_noise(s: &str) -> Result<SensorNoise, String> {
    s.parse()
}

fn parse_step_control(s: &str) -> Result<StepControl, String> {
    match s {
        "auto" => Ok(StepControl::Auto),
        "fixed" => Ok(StepControl::Fixed),
        "adaptive" => Ok(StepControl::Adaptive),
        other => Err(format!(
            "unknown step control '{other}'; use auto, fixed or adaptive"
        )),
    }
}

/// Runs `smspace trace`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let inputs = [
        ("--motors", Some(args.motors.as_path())),
        ("--env", args.env.env.as_deref()),
        ("--agent", args.agent.file()),
    ];
    super::common::spare_inputs(&[&args.out], &inputs)?;
    io::check_output_folder(&args.out)?;
    let (spec, agent) = args.agent.load()?;
    let learned = args.method == TraceMethod::Learned;
    let (trace, learn_params) = kernel_table(&args)?;
    let params = trace.check()?;
    if !learned && (args.budget.is_some() || !args.law.is_empty() || !learn_params.is_empty()) {
        anyhow::bail!("--budget, --law and --param learn.KEY apply to --method learned only");
    }
    let motors = io::read_matrix(
        &args.motors,
        Some(agent.motor_dim()),
        &format!("(M, {})", agent.motor_dim()),
    )?;
    let environment = match args.method {
        TraceMethod::Kinematic => args.env.resolve(&spec, agent.as_ref())?,
        TraceMethod::Sensory | TraceMethod::Learned => {
            Some(args.env.resolve(&spec, agent.as_ref())?.ok_or_else(|| {
                anyhow::anyhow!(
                    "--method {} needs an environment: give --env FILE or --env-seed S",
                    if learned { "learned" } else { "sensory" }
                )
            })?)
        }
    };
    let workspace = args.workspace.resolve(agent.as_ref())?;
    super::common::check_memory(
        "kernel sets",
        params.sets_bytes(motors.nrows() as u64, agent.motor_dim()),
        args.max_memory,
        "trace fewer motor rows per call, or lower --points",
    )?;
    let bar = Bar::new();
    let traced = if learned {
        let budget = args.budget.ok_or_else(|| {
            anyhow::anyhow!(
                "--method learned reads the agent within a budget: give --budget ROWS, the most sensor rows to read in all (babbling, then verifying the sets)"
            )
        })?;
        let budget = budget_params(
            BudgetParams {
                rounds: args.rounds,
                verify_points: args.verify_points,
                seed: args.seed,
                law: law_params(&args.law)?,
                ..BudgetParams::new(budget)
            },
            learn_params,
        )?;
        let Some(environment) = environment.as_ref() else {
            anyhow::bail!("--method learned needs an environment: give --env FILE or --env-seed S");
        };
        learned_sets(
            agent.as_ref(),
            environment,
            motors.view(),
            workspace,
            &budget,
            &trace,
            args.max_memory,
            &bar,
        )?
    } else {
        trace_sets(
            agent.as_ref(),
            environment.as_ref(),
            motors.view(),
            workspace.as_ref(),
            &params,
            &bar,
        )?
    };
    // Fewer than two kept sets (of two or more) leave nothing to compare: fail here,
    // naming the statuses and what each suggests, before writing anything.
    traced
        .report
        .summary
        .require(motors.nrows().min(2))
        .map_err(|e| anyhow::anyhow!("{e}. Nothing was written."))?;
    // The same writer as the pipeline's trace stage: the sets, the kept motor rows, which
    // sets are closed loops (for the curve metric) and the report.
    let mut outputs = io::Outputs::sparing(&super::common::present(&inputs));
    let [_, kept_path, _, _, report_path] = traced.write_into(&mut outputs, &args.out)?;
    outputs.commit()?;
    print_summary(&args, &traced, &params, &report_path, &kept_path);
    Ok(())
}

/// The `[kernel]` table the flags and `--param`s give (the learned route traces with
/// the sensory method on its law), and the `--param learn.KEY` entries set aside.
fn kernel_table(args: &Args) -> anyhow::Result<(TraceParams, Vec<(String, toml::Value)>)> {
    if let Some(value) = &args.old_noise {
        anyhow::bail!(
            "--noise is now --sensor-sigma (the standard deviation of one reading, in sensor units, or auto): write --sensor-sigma {value}"
        );
    }
    let trace = TraceParams {
        method: if args.method == TraceMethod::Learned {
            TraceMethod::Sensory
        } else {
            args.method
        },
        points: args.points,
        step: args.step,
        step_control: args.step_control,
        max_step: args.max_step,
        closure_tolerance: args.closure_tolerance,
        components: args.components,
        piece_starts: args.piece_starts,
        cover_step: args.cover_step,
        noise: args.sensor_sigma,
        ..TraceParams::default()
    };
    with_params(trace, &args.params)
}

/// What was traced, on stderr: the counts, the rows a budget spent, and every warning
/// (the law's, the budget's, the sets').
fn print_summary(
    args: &Args,
    traced: &smspace::kernel::TracedSets,
    params: &smspace::kernel::TraceValidParams,
    report_path: &std::path::Path,
    kept_path: &std::path::Path,
) {
    let summary = &traced.report.summary;
    eprintln!(
        "traced {} of {} sets ({:?}, {:?} steps); {} failed{}",
        summary.traced,
        summary.total,
        args.method,
        params.step_control(),
        summary.failed,
        if summary.failed > 0 {
            format!(
                " ({:?}; see {}; kept rows in {})",
                summary.by_status,
                report_path.display(),
                kept_path.display()
            )
        } else {
            String::new()
        }
    );
    if let Some(budget) = &traced.report.budget {
        let rows = &budget["rows"];
        eprintln!(
            "{} sensor rows read in all ({} babbling, {} for the agent's own slope, {} verifying the sets)",
            rows["total"], rows["babble"], rows["agent_rank"], rows["verify"]
        );
        for warning in budget["warnings"].as_array().into_iter().flatten() {
            eprintln!("warning: {}", warning.as_str().unwrap_or_default());
        }
    }
    if let Some(law) = &traced.report.law {
        for warning in law["warnings"].as_array().into_iter().flatten() {
            eprintln!("warning: {}", warning.as_str().unwrap_or_default());
        }
    }
    for warning in summary.warnings() {
        eprintln!("warning: {warning}");
    }
}

/// The [kernel] keys that have a flag of their own.
const KERNEL_FLAGS: [(&str, &str); 10] = [
    ("method", "method"),
    ("points", "points"),
    ("step", "step"),
    ("step_control", "step-control"),
    ("max_step", "max-step"),
    ("closure_tolerance", "closure-tolerance"),
    ("components", "components"),
    ("piece_starts", "piece-starts"),
    ("sensor_sigma", "sensor-sigma"),
    ("cover_step", "cover-step"),
];

/// [learn] keys that have a flag of their own.
const LEARN_FLAGS: [(&str, &str); 5] = [
    ("budget", "budget"),
    ("rounds", "rounds"),
    ("verify_points", "verify-points"),
    ("seed", "seed"),
    ("law", "law"),
];

/// `trace` with the `--param` keys of the [kernel] table set (read by the table's own
/// reader, which names an unknown key), and the `learn.KEY` ones set aside.
fn with_params(
    trace: TraceParams,
    params: &[(String, toml::Value)],
) -> anyhow::Result<(TraceParams, Vec<(String, toml::Value)>)> {
    let (learn, kernel) = split_params(params, "learn.");
    let trace = with_table_params(&trace, &kernel, &KERNEL_FLAGS, "kernel")?;
    Ok((trace, learn))
}

/// `budget` with the `--param learn.KEY` values set (read by the [learn] table's own
/// reader, which names an unknown key).
fn budget_params(
    budget: BudgetParams,
    learn: Vec<(String, toml::Value)>,
) -> anyhow::Result<BudgetParams> {
    with_table_params(&budget, &learn, &LEARN_FLAGS, "learn")
}

/// The law's parameters from `--law KEY=VALUE` pairs (a value read as JSON when it
/// parses, else as a string), checked by the law's own table.
fn law_params(pairs: &[String]) -> anyhow::Result<LawParams> {
    let mut table = serde_json::Map::new();
    for pair in pairs {
        let (key, value) = pair.split_once('=').ok_or_else(|| {
            anyhow::anyhow!("--law {pair}: give KEY=VALUE (e.g. --law invariants=9)")
        })?;
        let value = serde_json::from_str(value.trim())
            .unwrap_or_else(|_| serde_json::Value::String(value.trim().to_owned()));
        table.insert(key.trim().to_owned(), value);
    }
    serde_json::from_value(serde_json::Value::Object(table))
        .map_err(|e| anyhow::anyhow!("--law: {e} (the keys of smspace learn's law)"))
}

/// `--method learned`: the law learned from babbling `agent` within the budget, the
/// sets traced on it and verified; the report's `budget` holds the rows spent.
#[allow(clippy::too_many_arguments)] // The stage's own parameters, each checked.
fn learned_sets(
    agent: &dyn smspace::agent::Agent,
    environment: &smspace::agent::Environment,
    motors: ndarray::ArrayView2<'_, f64>,
    workspace: Option<smspace::agent::Workspace>,
    budget: &BudgetParams,
    trace: &TraceParams,
    max_memory: Option<u64>,
    bar: &Bar,
) -> anyhow::Result<TracedSets> {
    let law = budget.law.check()?;
    let found = learn_from_agent(
        agent,
        environment,
        motors,
        workspace,
        &budget.check()?,
        &law,
        trace,
        max_memory,
        bar,
    )?;
    Ok(found.into_traced())
}
