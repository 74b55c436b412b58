//! A level switch: the state carried to the new level, the two transition
//! states (old level, new level, same instant), the new coefficients.

use std::sync::Arc;
use std::time::Instant;

use super::runner::Runner;
use super::shadow::Shadow;
use super::SwitchOutcome;
use crate::estimate::Method;
use crate::lod::transfer_state;
use crate::plan::{Level, Prepared};
use crate::points::cloud::CloudMap;
use crate::sim::Simulation;

impl Runner {
    /// Run with `prepared`'s method and coefficients, its predicted error and
    /// error normaliser, and (when wanted) its shadow reference. The
    /// simulation must already be built with them at its level.
    pub(super) fn adopt(&mut self, prepared: &Arc<Prepared>) {
        self.method = prepared.method;
        self.material = prepared.material;
        self.predicted_error = Some(prepared.predicted_error);
        self.o_max = Some(prepared.o_max);
        self.shadow = self
            .shadow_wanted
            .then(|| Shadow::new(prepared.clone(), self.sim.topology().n_nodes));
        self.sync_replica();
    }

    pub(super) fn switch(
        &mut self,
        level: Level,
        prepared: Option<Arc<Prepared>>,
        mut sim: Simulation,
        cloud: Option<CloudMap>,
        settler: Option<Simulation>,
    ) -> Result<SwitchOutcome, String> {
        if prepared.as_ref().is_some_and(|p| p.level != level) {
            return Err(format!(
                "prepared for {}, asked for {level}",
                prepared.map_or(level, |p| p.level)
            ));
        }
        let previous = self.level;
        let old_topology = self.sim.topology().clone();
        let before = self.snapshot(true);
        let mut resampled = false;
        let state = match (self.cloud.as_mut(), cloud.as_ref()) {
            (Some(from), Some(to)) => from.carry(self.sim.state(), to),
            (None, None) => {
                if Arc::ptr_eq(&old_topology, sim.topology()) || old_topology.n_nodes == sim.topology().n_nodes {
                    self.sim.state().clone()
                } else {
                    resampled = true;
                    transfer_state(&old_topology, self.sim.state(), sim.topology()).map_err(|e| e.to_string())?
                }
            }
            _ => return Err("a switch between a cloth and a surface level".into()),
        };
        sim.set_state(state).map_err(|e| e.to_string())?;
        // Only down: a coarser level reads more in a finer shape than it
        // holds (docs/results.md, "Settling what a level cannot hold").
        let coarser = resampled && sim.topology().n_nodes < old_topology.n_nodes;
        if let Some(h) = self.switch_settle.filter(|_| coarser) {
            // Before the old level is let go: a refusal keeps it running.
            match settler {
                Some(mut twin) => crate::lod::settle_with(&mut sim, &mut twin),
                None => crate::lod::settle(&mut sim, h),
            }
            .map_err(|e| e.to_string())?;
        }
        self.sim = sim;
        self.carry_inputs();
        self.checkpoint = self.sim.state().clone();
        self.consecutive_divergences = 0;
        if cloud.is_some() {
            self.cloud = cloud;
        }
        self.level = level;
        self.coefficient_version += 1;
        match prepared {
            Some(prepared) => self.adopt(&prepared),
            None => {
                // At once: the coefficients the simulation was built with.
                self.method = Method::Same;
                self.material = self.sim.params().material;
                self.predicted_error = None;
                self.o_max = None;
                self.shadow = None;
                self.sync_replica();
            }
        }
        self.live_error = None;
        self.live_error_time = None;
        self.reanchor(Instant::now());
        self.update_status();
        let after = self.snapshot(true);
        let _ = self.transitions.send(Arc::new(before));
        let after = Arc::new(after);
        let _ = self.transitions.send(after.clone());
        self.states.send_replace(Some(after));
        Ok(SwitchOutcome {
            previous,
            level: self.level,
            method: self.method,
            material: self.material,
            predicted_error: self.predicted_error,
            dt: self.dt(),
            coefficient_version: self.coefficient_version,
            frame: self.frames,
        })
    }
}
