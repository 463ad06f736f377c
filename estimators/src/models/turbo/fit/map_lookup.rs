//! Reading an operating point off the engine map: the engine speed of a log that does not log
//! it, and the wastegate opening the model needs there.
//!
//! The map's points lie on speed lines (800, 1,050, 1,300, ... rpm: every point's speed
//! rounded to 50 rpm names its line). A quantity is read at a manifold pressure `p_im` by
//! linear interpolation along each line between the two points that bracket `p_im`, then
//! between the lines. Model-free except for what is read: the wastegate is the whole-model
//! check's solved position ([`super::check`]), the one quantity the map does not measure.

use std::collections::BTreeMap;

use super::{CheckReport, EnginePoint};

/// Speed-line key of a point: its speed rounded to 50 rpm.
fn line_key(p: &EnginePoint) -> i64 {
    (p.engine_speed_rev_s * 60.0 / 50.0).round() as i64 * 50
}

/// Per speed line (ascending): the line's mean speed (rad/s) and `value` interpolated
/// linearly in `p_im` at `p_im_pa` (lines that do not bracket it are left out).
fn along_lines(points: impl Iterator<Item = (EnginePoint, f64)>, p_im_pa: f64) -> Vec<(f64, f64)> {
    let mut lines: BTreeMap<i64, Vec<(EnginePoint, f64)>> = BTreeMap::new();
    for (p, v) in points {
        lines.entry(line_key(&p)).or_default().push((p, v));
    }
    let mut curve = Vec::new();
    for pts in lines.values_mut() {
        pts.sort_by(|a, b| a.0.p_im_pa.total_cmp(&b.0.p_im_pa));
        let speed = pts.iter().map(|p| p.0.engine_speed_rev_s).sum::<f64>() / pts.len() as f64
            * std::f64::consts::TAU;
        if let Some(w) = pts
            .windows(2)
            .find(|w| w[0].0.p_im_pa <= p_im_pa && p_im_pa <= w[1].0.p_im_pa)
        {
            let f = (p_im_pa - w[0].0.p_im_pa) / (w[1].0.p_im_pa - w[0].0.p_im_pa).max(1.0);
            curve.push((speed, w[0].1 + f * (w[1].1 - w[0].1)));
        }
    }
    curve
}

/// Engine speed (rad/s) at which the map passes `flow_kg_s` of air at `p_im_pa`: each line's
/// air flow at that pressure, then the speed between the two lines whose flows bracket it.
/// `None` when the point lies outside the map's speed lines.
pub fn speed_from_map(map: &[EnginePoint], p_im_pa: f64, flow_kg_s: f64) -> Option<f64> {
    let curve = along_lines(map.iter().map(|p| (*p, p.air_flow_kg_s)), p_im_pa);
    curve.windows(2).find_map(|w| {
        let ((s0, f0), (s1, f1)) = (w[0], w[1]);
        ((f0 - flow_kg_s) * (f1 - flow_kg_s) <= 0.0 && f1 != f0)
            .then(|| s0 + (flow_kg_s - f0) / (f1 - f0) * (s1 - s0))
    })
}

/// Wastegate opening (0..1) the model needs at engine speed `speed_rad_s` and manifold
/// pressure `p_im_pa`: the check's solved position at the map's points (saturated ones at
/// their limit), read along the lines and between the two lines around the speed. For a log
/// that does not record its wastegate, taken at an operating point the map covers, this is
/// the opening the engine's own boost control held there when the map was measured, in the
/// model's terms. `None` outside the map's lines.
pub fn wastegate_from_map(
    map: &[EnginePoint],
    check: &CheckReport,
    speed_rad_s: f64,
    p_im_pa: f64,
) -> Option<f64> {
    let solved = check
        .points
        .iter()
        .filter_map(|pc| map.get(pc.index).map(|p| (*p, pc.wastegate)));
    let curve = along_lines(solved, p_im_pa);
    curve.windows(2).find_map(|w| {
        let ((s0, g0), (s1, g1)) = (w[0], w[1]);
        (s0 <= speed_rad_s && speed_rad_s <= s1 && s1 > s0)
            .then(|| (g0 + (speed_rad_s - s0) / (s1 - s0) * (g1 - g0)).clamp(0.0, 1.0))
    })
}

/// The map's points on the two speed lines around `speed_rad_s` (what
/// [`wastegate_from_map`] reads there), or every point when the speed lies outside the lines.
pub fn points_around(map: &[EnginePoint], speed_rad_s: f64) -> Vec<EnginePoint> {
    let rpm = speed_rad_s * 60.0 / std::f64::consts::TAU;
    let keys: Vec<i64> = {
        let mut k: Vec<i64> = map.iter().map(line_key).collect();
        k.sort_unstable();
        k.dedup();
        k
    };
    let below = keys.iter().rev().find(|&&k| (k as f64) <= rpm);
    let above = keys.iter().find(|&&k| (k as f64) >= rpm);
    match (below, above) {
        (Some(&b), Some(&a)) => map
            .iter()
            .filter(|p| {
                let k = line_key(p);
                k == b || k == a
            })
            .copied()
            .collect(),
        _ => map.to_vec(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(rpm: f64, p_im_kpa: f64, flow_g_s: f64) -> EnginePoint {
        EnginePoint {
            p_af_pa: 100e3,
            p_ic_pa: 101e3,
            p_im_pa: p_im_kpa * 1e3,
            p_em_pa: 110e3,
            p_t_pa: 102e3,
            t_af_k: 298.0,
            t_ic_k: 300.0,
            t_im_k: 305.0,
            t_em_k: 900.0,
            t_t_k: 850.0,
            engine_speed_rev_s: rpm / 60.0,
            throttle_frac: 0.2,
            air_flow_kg_s: flow_g_s * 1e-3,
            lambda: 1.0,
        }
    }

    #[test]
    fn speed_is_interpolated_along_and_between_lines() {
        // 1,000 rpm: 10 g/s at 50 kPa, 20 g/s at 90 kPa; 2,000 rpm: twice that.
        let map = [
            point(1000.0, 50.0, 10.0),
            point(1000.0, 90.0, 20.0),
            point(2000.0, 50.0, 20.0),
            point(2000.0, 90.0, 40.0),
        ];
        // At 70 kPa the lines pass 15 and 30 g/s; 22.5 g/s lies halfway: 1,500 rpm.
        let s = speed_from_map(&map, 70e3, 22.5e-3).expect("inside");
        assert!((s * 60.0 / std::f64::consts::TAU - 1500.0).abs() < 1e-9);
        assert!(speed_from_map(&map, 70e3, 50e-3).is_none());
        assert!(speed_from_map(&map, 95e3, 22.5e-3).is_none());
        let around = points_around(&map, 1500.0 * std::f64::consts::TAU / 60.0);
        assert_eq!(around.len(), 4);
        assert_eq!(points_around(&map[..2], 1500.0).len(), 2);
    }
}
