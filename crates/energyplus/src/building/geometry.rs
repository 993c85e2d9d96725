//! The generated model's geometry: the zones of each storey and their surfaces (floors,
//! ceilings and roof, exterior and matched interzone walls) with the windows.

use super::{BuildingSpec, Zoning};
use crate::idf::{num, Idf};

impl BuildingSpec {
    /// Zones, floors, ceilings and walls (with their windows) of every storey.
    pub(super) fn add_geometry(&self, m: &mut Idf) {
        let plans = self.zone_plans();
        for f in 1..=self.storeys {
            for (suffix, poly) in &plans {
                let zone = format!("F{f}{suffix}");
                m.add(
                    "Zone",
                    &[
                        zone.clone(),
                        "0".into(),
                        "0".into(),
                        "0".into(),
                        "0".into(),
                        "1".into(),
                        "1".into(),
                        num(self.floor_to_floor_m),
                        "autocalculate".into(),
                    ],
                );
                self.add_floor_and_ceiling(m, f, suffix, poly);
                for i in 0..poly.len() {
                    self.add_wall(m, f, &plans, suffix, poly, i);
                }
            }
        }
    }

    /// Zone footprints of a storey, counterclockwise seen from above, with each zone's suffix
    /// (`F{storey}{suffix}`).
    fn zone_plans(&self) -> Vec<(&'static str, Vec<[f64; 2]>)> {
        let [l, w] = self.footprint_m;
        let d = self.perimeter_depth_m;
        match self.zoning {
            Zoning::OnePerFloor => vec![("", vec![[0.0, 0.0], [l, 0.0], [l, w], [0.0, w]])],
            Zoning::PerimeterCore => vec![
                ("_South", vec![[0.0, 0.0], [l, 0.0], [l - d, d], [d, d]]),
                ("_East", vec![[l, 0.0], [l, w], [l - d, w - d], [l - d, d]]),
                ("_North", vec![[l, w], [0.0, w], [d, w - d], [l - d, w - d]]),
                ("_West", vec![[0.0, w], [0.0, 0.0], [d, d], [d, w - d]]),
                (
                    "_Core",
                    vec![[d, d], [l - d, d], [l - d, w - d], [d, w - d]],
                ),
            ],
        }
    }

    /// The floor (on the ground, or over the zone below) and the ceiling (the roof, or under
    /// the zone above) of zone `F{f}{suffix}` with footprint `poly`.
    fn add_floor_and_ceiling(&self, m: &mut Idf, f: u32, suffix: &str, poly: &[[f64; 2]]) {
        let zone = format!("F{f}{suffix}");
        let z0 = (f - 1) as f64 * self.floor_to_floor_m;
        let z1 = z0 + self.floor_to_floor_m;
        // Floor: outward normal down -> clockwise seen from above.
        let floor: Vec<[f64; 3]> = poly.iter().rev().map(|p| [p[0], p[1], z0]).collect();
        let (fc, fb, fo) = if f == 1 {
            (
                "Ground Floor".to_string(),
                "Ground".to_string(),
                String::new(),
            )
        } else {
            (
                "Interior Floor".to_string(),
                "Surface".to_string(),
                format!("F{}{suffix} Ceiling", f - 1),
            )
        };
        add_surface(
            m,
            [
                &format!("{zone} Floor"),
                "Floor",
                &fc,
                &zone,
                &fb,
                &fo,
                "NoSun",
                "NoWind",
            ],
            &floor,
        );
        let ceil: Vec<[f64; 3]> = poly.iter().map(|p| [p[0], p[1], z1]).collect();
        let (ct, cc, cb, co, sun, wind) = if f == self.storeys {
            (
                "Roof",
                "Roof",
                "Outdoors",
                String::new(),
                "SunExposed",
                "WindExposed",
            )
        } else {
            (
                "Ceiling",
                "Interior Ceiling",
                "Surface",
                format!("F{}{suffix} Floor", f + 1),
                "NoSun",
                "NoWind",
            )
        };
        add_surface(
            m,
            [
                &format!("{zone} Ceiling"),
                ct,
                cc,
                &zone,
                cb,
                &co,
                sun,
                wind,
            ],
            &ceil,
        );
    }

    /// Wall `i + 1` of zone `F{f}{suffix}` (the edge from `poly[i]` to the next vertex): on the
    /// footprint's boundary an exterior wall with a centred strip window at the spec's
    /// window-to-wall ratio; inside, an interior wall facing its twin in the zone across
    /// (`plans`: the storey's zones).
    fn add_wall(
        &self,
        m: &mut Idf,
        f: u32,
        plans: &[(&str, Vec<[f64; 2]>)],
        suffix: &str,
        poly: &[[f64; 2]],
        i: usize,
    ) {
        let [l, w] = self.footprint_m;
        let h = self.floor_to_floor_m;
        let zone = format!("F{f}{suffix}");
        let z0 = (f - 1) as f64 * h;
        let z1 = z0 + h;
        let n = poly.len();
        let a = poly[i];
        let b = poly[(i + 1) % n];
        let wall = format!("{zone} Wall {}", i + 1);
        let pts = [
            [a[0], a[1], z1],
            [a[0], a[1], z0],
            [b[0], b[1], z0],
            [b[0], b[1], z1],
        ];
        let eq = |x: f64, y: f64| (x - y).abs() < 1e-9;
        let on_boundary = (eq(a[1], 0.0) && eq(b[1], 0.0))
            || (eq(a[0], l) && eq(b[0], l))
            || (eq(a[1], w) && eq(b[1], w))
            || (eq(a[0], 0.0) && eq(b[0], 0.0));
        if on_boundary {
            add_surface(
                m,
                [
                    &wall,
                    "Wall",
                    "Exterior Wall",
                    &zone,
                    "Outdoors",
                    "",
                    "SunExposed",
                    "WindExposed",
                ],
                &pts,
            );
            // A centred strip window with the wall's window-to-wall ratio.
            let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
            let win_len = len * 0.98;
            let win_h = (self.window_to_wall * len * h / win_len).min(h - 0.2);
            m.add(
                "Window",
                &[
                    format!("{wall} Window"),
                    "Window".into(),
                    wall,
                    "".into(),
                    "1".into(),
                    num(len * 0.01),
                    num((h - win_h) / 2.0),
                    num(win_len),
                    num(win_h),
                ],
            );
        } else {
            // The zone across: the one whose footprint has the same edge the other way round.
            let (other, other_poly) = plans
                .iter()
                .find(|(_, q)| (0..q.len()).any(|j| q[j] == b && q[(j + 1) % q.len()] == a))
                .expect("interior edge has a twin");
            let j = (0..other_poly.len())
                .find(|&j| other_poly[j] == b)
                .expect("twin edge");
            let facing = format!("F{f}{other} Wall {}", j + 1);
            add_surface(
                m,
                [
                    &wall,
                    "Wall",
                    "Interior Wall",
                    &zone,
                    "Surface",
                    &facing,
                    "NoSun",
                    "NoWind",
                ],
                &pts,
            );
        }
    }
}

/// A `BuildingSurface:Detailed`: `[name, type, construction, zone, outside boundary condition,
/// its object, sun exposure, wind exposure]` (the space field left empty), then the vertex
/// count and each vertex's x, y, z.
fn add_surface(m: &mut Idf, fields: [&str; 8], pts: &[[f64; 3]]) {
    let [name, kind, construction, zone, boundary, object, sun, wind] = fields;
    let mut s: Vec<String> = [
        name,
        kind,
        construction,
        zone,
        "",
        boundary,
        object,
        sun,
        wind,
    ]
    .iter()
    .map(|f| f.to_string())
    .collect();
    s.push("autocalculate".into());
    s.push(pts.len().to_string());
    s.extend(pts.iter().flat_map(|p| [num(p[0]), num(p[1]), num(p[2])]));
    m.add("BuildingSurface:Detailed", &s);
}
