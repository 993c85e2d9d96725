//! Solar geometry and the split of measured global horizontal radiation into its direct and
//! diffuse parts, for weather files built from stations that measure only GHI.
//!
//! Pure functions of angles and days; each follows pvlib-python's implementation of the cited
//! reference, and the tests hold them to values computed with pvlib 0.13.1:
//! - declination and equation of time: Spencer (1971), "Fourier series representation of the
//!   position of the sun", Search 2(5), 172 (pvlib `declination_spencer71`,
//!   `equation_of_time_spencer71`);
//! - zenith from hour angle, declination and latitude: Duffie & Beckman, *Solar Engineering of
//!   Thermal Processes*, eq. 1.6.5 (pvlib `solar_zenith_analytical`);
//! - extraterrestrial normal irradiance: Spencer (1971) distance factor with the solar constant
//!   1366.1 W/m2 (pvlib `get_extra_radiation`, method `spencer`);
//! - diffuse fraction: Erbs, Klein & Duffie (1982), "Estimation of the diffuse radiation fraction
//!   for hourly, daily and monthly-average global radiation", Solar Energy 28(4), 293-302, eq. 1
//!   (pvlib `erbs`).

use std::f64::consts::PI;

/// Solar constant, W/m2 (pvlib's default).
pub const SOLAR_CONSTANT_W_M2: f64 = 1366.1;

/// Smallest cosine of the zenith used in the clearness index (pvlib's default: zenith 86.27 deg).
pub const MIN_COS_ZENITH: f64 = 0.065;

/// Zenith above which all radiation is taken as diffuse, degrees (pvlib's default).
pub const MAX_ZENITH_DEG: f64 = 87.0;

/// Spencer's day angle, radians, for day of year `doy` (1 = January 1).
fn day_angle(doy: f64) -> f64 {
    2.0 * PI / 365.0 * (doy - 1.0)
}

/// Solar declination, radians (Spencer 1971).
pub fn declination(doy: f64) -> f64 {
    let b = day_angle(doy);
    0.006918 - 0.399912 * b.cos() + 0.070257 * b.sin() - 0.006758 * (2.0 * b).cos()
        + 0.000907 * (2.0 * b).sin()
        - 0.002697 * (3.0 * b).cos()
        + 0.00148 * (3.0 * b).sin()
}

/// Equation of time, minutes (Spencer 1971, as in Duffie & Beckman).
pub fn equation_of_time_min(doy: f64) -> f64 {
    let b = day_angle(doy);
    1440.0 / (2.0 * PI)
        * (0.0000075 + 0.001868 * b.cos()
            - 0.032077 * b.sin()
            - 0.014615 * (2.0 * b).cos()
            - 0.040849 * (2.0 * b).sin())
}

/// Extraterrestrial normal irradiance, W/m2, on day of year `doy` (Spencer's distance factor).
pub fn extraterrestrial_normal_w_m2(doy: f64) -> f64 {
    let b = day_angle(doy);
    SOLAR_CONSTANT_W_M2
        * (1.00011
            + 0.034221 * b.cos()
            + 0.00128 * b.sin()
            + 0.000719 * (2.0 * b).cos()
            + 7.7e-05 * (2.0 * b).sin())
}

/// Solar zenith angle, degrees, at `standard_hour` (hours after local standard midnight,
/// fractional) of day `doy`, for a site at `latitude_deg`, `longitude_deg` (east positive) whose
/// standard time is `time_zone_h` hours from UTC.
pub fn zenith_deg(
    doy: f64,
    standard_hour: f64,
    latitude_deg: f64,
    longitude_deg: f64,
    time_zone_h: f64,
) -> f64 {
    let hour_angle_deg = 15.0 * (standard_hour - time_zone_h - 12.0)
        + longitude_deg
        + equation_of_time_min(doy) / 4.0;
    let (lat, dec, w) = (
        latitude_deg.to_radians(),
        declination(doy),
        hour_angle_deg.to_radians(),
    );
    (dec.cos() * lat.cos() * w.cos() + dec.sin() * lat.sin())
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

/// Global horizontal radiation split into its parts (Erbs et al. 1982).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Split {
    /// Direct normal, same unit as the global horizontal given.
    pub direct_normal: f64,
    /// Diffuse horizontal, same unit as the global horizontal given.
    pub diffuse_horizontal: f64,
    /// Clearness index kt (global over extraterrestrial horizontal), 0..=1.
    pub clearness_index: f64,
}

/// Erbs diffuse fraction of global horizontal radiation `ghi` (W/m2, or Wh/m2 over an hour) at
/// zenith `zenith_deg` on day `doy`; kt is clipped to 0..=1 and the zenith's cosine held at
/// [`MIN_COS_ZENITH`] or above, as pvlib does; above [`MAX_ZENITH_DEG`] all of it is diffuse.
pub fn erbs(ghi: f64, zenith_deg: f64, doy: f64) -> Split {
    let cos_z = zenith_deg.to_radians().cos();
    let horizontal_extra = extraterrestrial_normal_w_m2(doy) * cos_z.max(MIN_COS_ZENITH);
    let kt = (ghi / horizontal_extra).clamp(0.0, 1.0);
    let diffuse_fraction = if kt <= 0.22 {
        1.0 - 0.09 * kt
    } else if kt <= 0.8 {
        0.9511 - 0.1604 * kt + 4.388 * kt.powi(2) - 16.638 * kt.powi(3) + 12.336 * kt.powi(4)
    } else {
        0.165
    };
    let dhi = diffuse_fraction * ghi;
    let dni = (ghi - dhi) / cos_z;
    if zenith_deg > MAX_ZENITH_DEG || ghi < 0.0 || dni < 0.0 {
        return Split {
            direct_normal: 0.0,
            diffuse_horizontal: ghi,
            clearness_index: kt,
        };
    }
    Split {
        direct_normal: dni,
        diffuse_horizontal: dhi,
        clearness_index: kt,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // Reference values computed with pvlib 0.13.1 (numpy 2): see the test's comments for the
    // calls. Tolerances are round-off, not approximation: the formulas are the same.

    #[test]
    fn declination_equation_of_time_and_extraterrestrial_match_pvlib() {
        // pvlib.solarposition.declination_spencer71(doy), equation_of_time_spencer71(doy),
        // pvlib.irradiance.get_extra_radiation(doy, method='spencer')
        let cases = [
            (1.0, -0.402449, -2.919678, 1413.981805),
            (80.0, -0.001151, -7.873670, 1376.892361),
            (172.0, 0.409315, -1.343725, 1321.623593),
            (355.0, -0.408754, 2.155086, 1412.708564),
        ];
        for (doy, dec, eot, extra) in cases {
            assert!((declination(doy) - dec).abs() < 1e-6, "doy {doy}");
            assert!((equation_of_time_min(doy) - eot).abs() < 1e-6, "doy {doy}");
            assert!(
                (extraterrestrial_normal_w_m2(doy) - extra).abs() < 1e-3,
                "doy {doy}"
            );
        }
    }

    #[test]
    fn zenith_matches_pvlib_analytical() {
        // Golden, CO (39.74 N, -105.18 E, UTC-7): pvlib.solarposition.solar_zenith_analytical
        // with hour_angle(times, -105.18, equation_of_time_spencer71(doy)) at local standard
        // times 2017-06-21 12:30 and 2017-12-21 08:30 (NREL SPA, pvlib spa_python, gives
        // 17.30 and 79.76 deg: the analytical zenith is within 0.1 deg, ample for hourly data).
        let z1 = zenith_deg(172.0, 12.5, 39.74, -105.18, -7.0);
        let z2 = zenith_deg(355.0, 8.5, 39.74, -105.18, -7.0);
        assert!((z1 - 17.325190).abs() < 1e-4, "{z1}");
        assert!((z2 - 79.692010).abs() < 1e-4, "{z2}");
    }

    #[test]
    fn erbs_matches_pvlib() {
        // pvlib.irradiance.erbs(ghi, zenith, doy): (ghi, zenith, doy) -> (dni, dhi, kt)
        let cases = [
            (800.0, 30.0, 172.0, 696.885129, 196.479775, 0.698959),
            (300.0, 60.0, 15.0, 119.183363, 240.408318, 0.424633),
            (50.0, 80.0, 355.0, 5.281892, 49.082809, 0.203820),
            (1000.0, 20.0, 180.0, 888.588440, 165.0, 0.805796),
            (10.0, 88.0, 100.0, 0.0, 10.0, 0.113057),
        ];
        for (ghi, z, doy, dni, dhi, kt) in cases {
            let s = erbs(ghi, z, doy);
            assert!((s.direct_normal - dni).abs() < 1e-5, "{ghi} {z}: {s:?}");
            assert!(
                (s.diffuse_horizontal - dhi).abs() < 1e-5,
                "{ghi} {z}: {s:?}"
            );
            assert!((s.clearness_index - kt).abs() < 1e-6, "{ghi} {z}: {s:?}");
        }
    }
}
