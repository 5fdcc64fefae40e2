//! `smspace.learn`: kernel sets from recorded sensorimotor logs, as `smspace learn`
//! computes them ([`smspace::learn`]): the law `ŝ(m)` learned from one or several logs
//! (motor and sensor arrays, one pair per environment), then the sets `ŝ(m) = ŝ(m^i)`
//! traced through each start with the sensory method.
//!
//! The keyword arguments are the `[data.law]` keys ([`LawParams`]) and the tracing keys
//! ([`TraceParams`], from the learned law's defaults, [`law_trace_params`]), told apart
//! by name; an unknown key is refused by the table it would have gone to.

use std::path::PathBuf;
use std::sync::Arc;

use numpy::{PyArray1, PyArray2, PyArray3, PyReadonlyArray2};
use pyo3::prelude::*;
use serde_json::{Map, Value};
use smspace::kernel::TraceParams;
use smspace::learn::budget::{learn_from_agent, BudgetParams};
use smspace::learn::{
    declared_space, law_trace_params, learn_with_progress, parse_motor_declarations, trace_learned,
    LawParams, LawValidParams, LogFiles, SensorimotorLog,
};

use crate::agent::Agent;
use crate::host::run_interruptible;
use crate::progress::PyProgress;
use crate::stages::{check_finite, traced_outputs};
use crate::{from_json, to_py_err, value_error};

/// The law's parameters and the tracing parameters, checked, from one JSON object of
/// keyword arguments: the keys [`LawParams`] has go to the law, the others to the
/// tracing.
fn split_params(json: &str) -> PyResult<(LawValidParams, TraceParams)> {
    let given: Map<String, Value> = from_json(json, "learning parameters")?;
    let law_keys = match serde_json::to_value(LawParams::default()) {
        Ok(Value::Object(fields)) => fields,
        _ => Map::new(),
    };
    let mut trace = match serde_json::to_value(law_trace_params()) {
        Ok(Value::Object(fields)) => fields,
        _ => Map::new(),
    };
    let mut law = Map::new();
    for (key, value) in given {
        if law_keys.contains_key(&key) {
            law.insert(key, value);
        } else {
            trace.insert(key, value);
        }
    }
    let law: LawParams = serde_json::from_value(Value::Object(law))
        .map_err(|e| value_error(format!("invalid law parameters: {e}")))?;
    let trace: TraceParams = serde_json::from_value(Value::Object(trace)).map_err(|e| {
        value_error(format!(
            "invalid tracing parameters: {e} (the other keywords are the law's: {})",
            law_keys.keys().cloned().collect::<Vec<_>>().join(", ")
        ))
    })?;
    let law = law.check().map_err(to_py_err)?;
    trace.check().map_err(to_py_err)?;
    Ok((law, trace))
}

/// The logs from their arrays, named `motors[i]` and `sensors[i]` in messages.
fn logs_of(
    motors: &[PyReadonlyArray2<'_, f64>],
    sensors: &[PyReadonlyArray2<'_, f64>],
    period: &str,
) -> PyResult<(Vec<SensorimotorLog>, smspace::agent::MotorSpace)> {
    if motors.is_empty() || motors.len() != sensors.len() {
        return Err(value_error(format!(
            "{} motor arrays but {} sensor arrays: give one pair per log (at least one)",
            motors.len(),
            sensors.len()
        )));
    }
    let declarations = parse_motor_declarations(period)
        .map_err(|reason| value_error(format!("period={period:?}: {reason}")))?;
    let name = |what: &str, i: usize| PathBuf::from(format!("{what}[{i}]"));
    let space = declared_space(&declarations, motors[0].as_array(), &name("motors", 0))
        .map_err(to_py_err)?;
    let logs = motors
        .iter()
        .zip(sensors)
        .enumerate()
        .map(|(i, (m, s))| {
            check_finite(m.as_array().iter(), &format!("motors[{i}]"))?;
            check_finite(s.as_array().iter(), &format!("sensors[{i}]"))?;
            let files = LogFiles {
                motors: name("motors", i),
                sensors: name("sensors", i),
            };
            SensorimotorLog::new(
                m.as_array().to_owned(),
                s.as_array().to_owned(),
                files,
                &space,
            )
            .map_err(to_py_err)
        })
        .collect::<PyResult<Vec<_>>>()?;
    Ok((logs, space))
}

/// `_learn(motors, sensors, starts, period, params, memory_limit_bytes, progress)`: the
/// kernel sets traced on the law learned from the logs, `(sets (M, P, N), kept (M,),
/// closed (M,), pieces (M, P), report_json, law_json)`: the tracing report (with the
/// summary's `warnings`) and the law's (`sets.law.json`, with what tracing showed).
#[pyfunction]
#[pyo3(signature = (motors, sensors, starts, period, params, memory_limit_bytes=None, progress=None))]
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn _learn<'py>(
    py: Python<'py>,
    motors: Vec<PyReadonlyArray2<'py, f64>>,
    sensors: Vec<PyReadonlyArray2<'py, f64>>,
    starts: PyReadonlyArray2<'py, f64>,
    period: &str,
    params: &str,
    memory_limit_bytes: Option<u64>,
    progress: Option<Py<PyAny>>,
) -> PyResult<(
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray2<i64>>,
    String,
    String,
)> {
    let (law_params, trace) = split_params(params)?;
    let (logs, space) = logs_of(&motors, &sensors, period)?;
    let starts = starts.as_array().to_owned();
    check_finite(starts.iter(), "starts")?;
    if starts.ncols() != space.dim() {
        return Err(value_error(format!(
            "starts has {} columns but the logs have {} motors; give one start per row, (M, {})",
            starts.ncols(),
            space.dim(),
            space.dim()
        )));
    }
    let limit = smspace_pipeline::front::learn_memory_limit(memory_limit_bytes);
    let progress = Arc::new(PyProgress::new(progress));
    let interrupts = [progress.interrupt()];
    let shared = progress.clone();
    let rows = starts.nrows();
    let learned = run_interruptible(py, &interrupts, move || {
        let law = learn_with_progress(&logs, &space, &law_params, Some(limit), shared.as_ref())?;
        drop(logs);
        let traced = trace_learned(&law, starts.view(), &trace, shared.as_ref())?;
        let report = law.report().with_trace(&traced.report.summary);
        Ok::<_, smspace::learn::LearnError>((traced, report))
    })?;
    progress.check()?;
    let (traced, report) = learned.map_err(to_py_err)?;
    let law = serde_json::to_string(&report).map_err(|e| value_error(e.to_string()))?;
    let (sets, kept, closed, pieces, trace_report) = traced_outputs(py, traced, rows)?;
    Ok((sets, kept, closed, pieces, trace_report, law))
}

/// `_learn_agent(agent, starts, budget_json, params_json, env, memory_limit_bytes,
/// progress)`: the kernel sets traced on the law learned from babbling `agent` within
/// a budget of sensor rows ([`learn_from_agent`]), verified against it; `(sets, kept,
/// closed, pieces, report_json, law_json, budget_json)`: the tracing report, the law's,
/// and the budget's (rows spent by phase, each set's verification).
#[pyfunction]
#[pyo3(signature = (agent, starts, budget, params, env=None, workspace=None, memory_limit_bytes=None, progress=None))]
#[allow(clippy::type_complexity, clippy::too_many_arguments)]
fn _learn_agent<'py>(
    py: Python<'py>,
    agent: &Agent,
    starts: PyReadonlyArray2<'py, f64>,
    budget: &str,
    params: &str,
    env: Option<&Bound<'py, PyAny>>,
    workspace: Option<&Bound<'py, PyAny>>,
    memory_limit_bytes: Option<u64>,
    progress: Option<Py<PyAny>>,
) -> PyResult<(
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray2<i64>>,
    String,
    String,
    String,
)> {
    let budget: BudgetParams = from_json(budget, "budget parameters")?;
    let budget = budget.check().map_err(to_py_err)?;
    let (law_params, trace) = split_params(params)?;
    // A rank the agent's motors cannot have is refused before any row is read.
    law_params
        .check_rank(agent.law.motor_dim())
        .map_err(to_py_err)?;
    let starts = starts.as_array().to_owned();
    check_finite(starts.iter(), "starts")?;
    let environment = agent.environment(env)?;
    let workspace = crate::stages::resolve_workspace(agent, workspace)?;
    let limit = smspace_pipeline::front::learn_memory_limit(memory_limit_bytes);
    let progress = Arc::new(PyProgress::new(progress));
    let mut interrupts = agent.interrupts();
    interrupts.push(progress.interrupt());
    let (law, shared) = (agent.law.clone(), progress.clone());
    let rows = starts.nrows();
    let learned = run_interruptible(py, &interrupts, move || {
        learn_from_agent(
            law.as_ref(),
            &environment,
            starts.view(),
            workspace,
            &budget,
            &law_params,
            &trace,
            Some(limit),
            shared.as_ref(),
        )
    })?;
    agent.check_callbacks()?;
    progress.check()?;
    let budgeted = learned.map_err(to_py_err)?;
    let law = serde_json::to_string(&budgeted.law).map_err(|e| value_error(e.to_string()))?;
    let spent = budgeted
        .spent_report()
        .ok_or_else(|| value_error("the budget's report did not serialise".to_owned()))?;
    let (sets, kept, closed, pieces, report) = traced_outputs(py, budgeted.traced, rows)?;
    Ok((sets, kept, closed, pieces, report, law, spent.to_string()))
}

/// Adds `_learn` and `_learn_agent` to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(_learn, m)?)?;
    m.add_function(wrap_pyfunction!(_learn_agent, m)?)?;
    Ok(())
}
