//! A level switch: the state carried to the new level, the two transition
//! states (old level, new level, same instant), the new coefficients.

use std::sync::Arc;
use std::time::Instant;

use super::runner::Runner;
use super::{SwitchError, SwitchOutcome};
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
        self.live.adopt(prepared, self.sim.topology().n_nodes);
        self.sync_replica();
    }

    pub(super) fn switch(
        &mut self,
        level: Level,
        prepared: Option<Arc<Prepared>>,
        mut sim: Simulation,
        cloud: Option<CloudMap>,
        settler: Option<Simulation>,
    ) -> Result<SwitchOutcome, SwitchError> {
        if let Some(p) = prepared.as_ref().filter(|p| p.level != level) {
            return Err(SwitchError::PreparedForAnother {
                prepared: p.level,
                asked: level,
            });
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
                    transfer_state(&old_topology, self.sim.state(), sim.topology()).map_err(SwitchError::Transfer)?
                }
            }
            _ => return Err(SwitchError::KindChange),
        };
        sim.set_state(state).map_err(SwitchError::State)?;
        // Only down: a coarser level reads more in a finer shape than it
        // holds (the lab's NOTEBOOK.md, "Settling what a level cannot hold").
        let coarser = resampled && sim.topology().n_nodes < old_topology.n_nodes;
        if let Some(h) = self.switch_settle.filter(|_| coarser) {
            // Before the old level is let go: a refusal keeps it running.
            match settler {
                Some(mut twin) => crate::lod::settle_with(&mut sim, &mut twin),
                None => crate::lod::settle(&mut sim, h),
            }
            .map_err(SwitchError::Settle)?;
        }
        self.sim = sim;
        self.carry_inputs();
        self.divergence.new_level(self.sim.state());
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
                self.live.drop_reference();
                self.sync_replica();
            }
        }
        self.live.clear();
        self.pacing.reanchor(Instant::now());
        self.update_status();
        let after = self.snapshot(true);
        self.publishing.transition(before, after);
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
