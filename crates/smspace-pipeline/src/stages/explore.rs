//! `explore`: motor babbling in the working space and the probe grid (paper section
//! 3.2, step 1), in the experiment's environments.

use std::path::Path;

use serde::Serialize;

use super::{Keyed, Stage, StageContext, StageInput, World};
use crate::data::RunData;
use crate::manifest::StageId;
use ndarray::Array2;
use smspace::agent::GroundTruth;
use smspace::explore::{explore_with, Exploration, ExploreParams};
use smspace::io::Outputs;

/// The `explore` stage: the `[exploration]` table.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ExploreStage {
    /// Babbling and probe parameters.
    pub exploration: ExploreParams,
}

/// What `explore` reads.
#[derive(Debug, Clone, Copy)]
pub struct ExploreInput<'a> {
    /// The agent, environments and working space.
    pub world: &'a Keyed<World>,
}

impl StageInput for ExploreInput<'_> {
    fn keys(&self) -> Vec<&str> {
        vec![&self.world.key]
    }
}

/// With `[data]`: `exploration.n` reference samples of the log (seeded by
/// `exploration.seed`) instead of babbling; their poses when the agent has a ground
/// truth (a simulated log), for evaluation only.
fn pick_references(
    world: &World,
    data: &RunData,
    exploration: &ExploreParams,
) -> crate::Result<Exploration> {
    let motors = data.pick(world.simulator(), exploration.n, exploration.seed)?;
    let ground_truth = world
        .agent
        .ground_truth()
        .map(|observer| GroundTruth::observe(observer, motors.view()))
        .transpose()
        .map_err(smspace::explore::ExploreError::from)?;
    let probes = Array2::from_elem((motors.nrows(), 3), -1);
    Ok(Exploration {
        motors,
        ground_truth,
        probes,
        workspace: world.workspace,
    })
}

/// The file of environment `i` (0: the main one).
fn environment_file(i: usize) -> String {
    if i == 0 {
        "environment.json".to_owned()
    } else {
        format!("environment-{}.json", i + 1)
    }
}

impl Stage for ExploreStage {
    const ID: StageId = StageId::Explore;
    type Input<'a> = ExploreInput<'a>;
    type Output = Exploration;

    fn compute(
        &self,
        input: &ExploreInput<'_>,
        context: &StageContext<'_>,
    ) -> crate::Result<Exploration> {
        let world = &input.world.value;
        if let Some(data) = &world.data {
            return pick_references(world, data, &self.exploration);
        }
        Ok(explore_with(
            world.agent.as_ref(),
            &self.exploration,
            world.workspace,
            context.progress,
        )?)
    }

    fn save(
        &self,
        input: &ExploreInput<'_>,
        exploration: &Exploration,
        outputs: &mut Outputs,
        dir: &Path,
    ) -> crate::Result<()> {
        let world = &input.world.value;
        exploration.write_into(outputs, dir, &world.agent_config, &self.exploration)?;
        for (i, env) in world.environments.iter().enumerate() {
            outputs.json(&dir.join(environment_file(i)), env)?;
        }
        Ok(())
    }

    fn load(&self, input: &ExploreInput<'_>, dir: &Path) -> crate::Result<Exploration> {
        let world = &input.world.value;
        Ok(Exploration::load(
            dir,
            world.agent.as_ref(),
            world.workspace,
        )?)
    }

    fn summary(&self, x: &Exploration) -> String {
        let probes = x.probe_count();
        format!(
            "{} configurations ({} babbled, {probes} probes)",
            x.motors.nrows(),
            x.motors.nrows() - probes,
        )
    }
}
