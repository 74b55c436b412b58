//! What [`super::Simulation`] refuses: parameters, loads and colliders
//! checked before a cloth is built or changed, each error naming what was
//! wrong.

use super::contact::{Collider, Shape};
use super::params::{SimParams, SpringClass};
use super::{vec3, Loads, PinPath, SimError};

pub(super) fn invalid(name: impl Into<String>, value: f64, reason: &'static str) -> SimError {
    SimError::InvalidParameter {
        name: name.into(),
        value,
        reason,
    }
}

pub(super) fn validate_params(p: &SimParams) -> Result<(), SimError> {
    if !(p.dt.is_finite() && p.dt > 0.0) {
        return Err(invalid("dt", p.dt, "the time step must be positive and finite"));
    }
    for class in SpringClass::ALL {
        let c = p.material.get(class);
        if !(c.k.is_finite() && c.k >= 0.0) {
            return Err(invalid(format!("{class}.k"), c.k, "stiffness must be finite and ≥ 0"));
        }
        if !(c.c.is_finite() && c.c >= 0.0) {
            return Err(invalid(format!("{class}.c"), c.c, "damping must be finite and ≥ 0"));
        }
    }
    if let Some((c, &g)) = p.gravity.iter().enumerate().find(|(_, g)| !g.is_finite()) {
        return Err(invalid(format!("gravity[{c}]"), g, "gravity must be finite"));
    }
    if !(p.drag.is_finite() && p.drag >= 0.0) {
        return Err(invalid("drag", p.drag, "drag must be finite and ≥ 0"));
    }
    if let Some(s) = p.self_contact {
        if !(s.thickness.is_finite() && s.thickness > 0.0) {
            return Err(invalid(
                "self_contact.thickness",
                s.thickness,
                "the cloth's thickness must be positive and finite (m)",
            ));
        }
        if !(s.friction.is_finite() && s.friction >= 0.0) {
            return Err(invalid(
                "self_contact.friction",
                s.friction,
                "friction must be finite and ≥ 0",
            ));
        }
    }
    if let Some(a) = p.stiffness_adjustment {
        if !(a.allowed.is_finite() && a.allowed >= 0.0) {
            return Err(invalid(
                "stiffness_adjustment.allowed",
                a.allowed,
                "allowed strain must be finite and ≥ 0",
            ));
        }
    }
    if let Some(l) = p.strain_limit {
        if !(l.max_strain.is_finite() && l.max_strain >= 0.0) {
            return Err(invalid(
                "strain_limit.max_strain",
                l.max_strain,
                "maximum strain must be finite and ≥ 0",
            ));
        }
        if !(l.tolerance.is_finite() && l.tolerance >= 0.0) {
            return Err(invalid(
                "strain_limit.tolerance",
                l.tolerance,
                "tolerance must be finite and ≥ 0",
            ));
        }
    }
    if !(p.cg.tolerance.is_finite() && p.cg.tolerance > 0.0) {
        return Err(invalid("cg.tolerance", p.cg.tolerance, "CG tolerance must be positive"));
    }
    if p.cg.max_iterations == 0 {
        return Err(invalid("cg.max_iterations", 0.0, "CG needs at least one iteration"));
    }
    Ok(())
}

/// A node set with one share each (`shares` names the shares, `what` the
/// set in errors), every node in a cloth of `n` nodes.
pub(super) fn check_node_shares(
    nodes: &[u32],
    shares: &[f64],
    n: usize,
    what: &'static str,
    shares_what: &'static str,
) -> Result<(), SimError> {
    if nodes.len() != shares.len() {
        return Err(SimError::SizeMismatch {
            what: shares_what,
            got: shares.len(),
            expected: nodes.len(),
        });
    }
    if let Some(&k) = nodes.iter().find(|&&k| k as usize >= n) {
        return Err(SimError::NodeOutOfRange {
            what,
            node: k,
            n_nodes: n,
        });
    }
    Ok(())
}

pub(super) fn validate_loads(loads: &Loads, n: usize) -> Result<(), SimError> {
    for (i, load) in loads.forces.iter().enumerate() {
        check_node_shares(&load.nodes, &load.shares, n, "force", "load shares")?;
        if let Some(&f) = load.force.iter().chain(&load.shares).find(|f| !f.is_finite()) {
            return Err(invalid(
                format!("forces[{i}]"),
                f,
                "force components and shares must be finite",
            ));
        }
    }
    if let Some(w) = &loads.wind {
        let all = w.velocity.iter().chain([&w.air_density, &w.drag_coefficient]);
        if let Some(&x) = all.clone().find(|x| !x.is_finite()) {
            return Err(invalid("wind", x, "wind values must be finite"));
        }
        if w.air_density < 0.0 || w.drag_coefficient < 0.0 {
            return Err(invalid(
                "wind",
                w.air_density.min(w.drag_coefficient),
                "air density and drag coefficient must be ≥ 0",
            ));
        }
    }
    for (i, t) in loads.tethers.iter().enumerate() {
        if t.node as usize >= n {
            return Err(SimError::NodeOutOfRange {
                what: "tether",
                node: t.node,
                n_nodes: n,
            });
        }
        if let Some(&x) = t
            .target
            .iter()
            .chain([&t.stiffness, &t.damping])
            .find(|x| !x.is_finite())
        {
            return Err(invalid(
                format!("tethers[{i}]"),
                x,
                "tether target, stiffness and damping must be finite",
            ));
        }
        if t.stiffness < 0.0 || t.damping < 0.0 {
            return Err(invalid(
                format!("tethers[{i}]"),
                t.stiffness.min(t.damping),
                "tether stiffness and damping must be ≥ 0",
            ));
        }
    }
    for (i, body) in loads.colliders.iter().enumerate() {
        validate_collider(i, body)?;
    }
    for pin in &loads.pins {
        if pin.node as usize >= n {
            return Err(SimError::NodeOutOfRange {
                what: "pin",
                node: pin.node,
                n_nodes: n,
            });
        }
        if pin.anchor.iter().any(|x| !x.is_finite()) {
            return Err(invalid(
                format!("pin on node {}", pin.node),
                f64::NAN,
                "pin anchor must be finite",
            ));
        }
    }
    Ok(())
}

fn validate_collider(i: usize, body: &Collider) -> Result<(), SimError> {
    let name = |what: &str| format!("colliders[{i}].{what}");
    let speed = match body.path {
        PinPath::Fixed => 0.0,
        PinPath::Linear { velocity, .. } => vec3::norm(velocity),
        PinPath::Sine { amplitude, frequency } => vec3::norm(amplitude) * frequency,
    };
    let checks: [(&str, f64, bool, &'static str); 4] = [
        ("position", vec3::norm(body.position), true, "must be finite"),
        ("path", speed, true, "must be finite"),
        (
            "friction",
            body.friction,
            body.friction >= 0.0,
            "must be finite and ≥ 0",
        ),
        (
            "clearance",
            body.clearance,
            body.clearance >= 0.0,
            "must be finite and ≥ 0",
        ),
    ];
    for (what, x, ok, reason) in checks {
        if !(x.is_finite() && ok) {
            return Err(invalid(name(what), x, reason));
        }
    }
    match body.shape {
        Shape::Plane { normal } => {
            if !((vec3::norm(normal) - 1.0).abs() < 1e-9) {
                return Err(invalid(
                    name("normal"),
                    vec3::norm(normal),
                    "a plane's normal must be a unit vector",
                ));
            }
        }
        Shape::Sphere { radius } | Shape::Capsule { radius, .. } => {
            if !(radius.is_finite() && radius > 0.0) {
                return Err(invalid(name("radius"), radius, "must be finite and > 0"));
            }
            if let Shape::Capsule { half_axis, .. } = body.shape {
                if !vec3::norm(half_axis).is_finite() {
                    return Err(invalid(name("half_axis"), vec3::norm(half_axis), "must be finite"));
                }
            }
        }
        Shape::Cuboid { half_extents } => {
            if let Some(&e) = half_extents.iter().find(|e| !(e.is_finite() && **e > 0.0)) {
                return Err(invalid(name("half_extents"), e, "each must be finite and > 0"));
            }
        }
        Shape::Cylinder { radius, half_height } => {
            for (field, x) in [("radius", radius), ("half_height", half_height)] {
                if !(x.is_finite() && x > 0.0) {
                    return Err(invalid(name(field), x, "must be finite and > 0"));
                }
            }
        }
    }
    Ok(())
}
