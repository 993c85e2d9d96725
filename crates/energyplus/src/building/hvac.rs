//! The generated model's HVAC: the air side (HVACTemplate objects: the thermostat, the zones'
//! outdoor air, then the spec's [`HvacSystem`]), the chilled- and hot-water plant, and the
//! domestic hot water heater.

use serde::{Deserialize, Serialize};

use super::{value, BuildingSpec, HeatingSource, DESIGN_CHILLED_WATER_C, DESIGN_SUPPLY_AIR_C};
use crate::idf::{num, Idf};
use crate::params::ParameterValues;
use crate::Error;

/// The HVAC system the generator writes.
#[derive(
    Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum HvacSystem {
    /// VAV with hot-water reheat on the air-handling units (the reference building's system):
    /// the AHUs supply cold air all year and each zone's box reheats it.
    #[default]
    VavReheat,
    /// A dedicated outdoor-air system per AHU (100 % outdoor air at the zones' occupied
    /// outdoor-air rate, running at occupied hours only; optional sensible heat recovery; its
    /// coils at the supply-air and preheat set-points) and a four-pipe fan coil per zone on the
    /// same chilled- and hot-water loops, cycling with the load around the clock. Zones are
    /// heated and cooled by water at the zone, with ventilation decoupled and no reheat: the
    /// energy pattern of radiant slabs or chilled beams with a DOAS, which the HVACTemplate
    /// objects cannot write directly. The DOAS's terminals hold their design flow (the
    /// templates ignore the zones' outdoor-air schedule), so this system has no
    /// `outdoor_air_ach_unoccupied` parameter: its unoccupied outdoor air is none.
    DoasFanCoil,
}

impl HvacSystem {
    pub(super) fn is_default(&self) -> bool {
        *self == HvacSystem::default()
    }

    /// The generator's parameters this system does not have, each with the reason.
    pub(super) fn omitted(self) -> &'static [(&'static str, &'static str)] {
        match self {
            HvacSystem::VavReheat => &[],
            HvacSystem::DoasFanCoil => &[(
                "outdoor_air_ach_unoccupied",
                "hvac = \"doas_fan_coil\" has none: its DOAS runs at occupied hours only",
            )],
        }
    }
}

impl BuildingSpec {
    /// The air side of the HVAC (HVACTemplate objects): the thermostat, the zones' outdoor air,
    /// then the spec's [`HvacSystem`].
    pub(super) fn add_air_systems(&self, m: &mut Idf, v: &ParameterValues) -> Result<(), Error> {
        let oa_occ = value(v, "outdoor_air_ach_occupied")?;
        m.add(
            "HVACTemplate:Thermostat",
            &["Thermostat", "Heating Setpoint", "", "Cooling Setpoint", ""],
        );
        m.add(
            "DesignSpecification:OutdoorAir",
            &[
                "Outdoor Air".to_string(),
                "AirChanges/Hour".into(),
                "".into(),
                "".into(),
                "".into(),
                num(oa_occ),
                "Outdoor Air Fraction".into(),
            ],
        );
        match self.hvac {
            HvacSystem::VavReheat => self.add_vav_reheat(m),
            HvacSystem::DoasFanCoil => self.add_doas_fan_coils(m),
        }
        Ok(())
    }

    /// One VAV terminal with hot-water reheat per zone and the VAV air-handling units.
    fn add_vav_reheat(&self, m: &mut Idf) {
        let zones = self.zone_names();
        let ahus = self.ahu_count();
        for (i, z) in zones.iter().enumerate() {
            let ahu = self.ahu_of_zone(i);
            let mut f = vec![
                z.clone(),
                format!("AHU{ahu}"),
                "Thermostat".into(),
                "autosize".into(),
                "".into(),
                "".into(),
                "Constant".into(),
                "0.3".into(),
                "".into(),
                "".into(),
                "DetailedSpecification".into(),
                "".into(),
                "".into(),
                "".into(),
                "HotWater".into(),
                "".into(),
                "Reverse".into(),
            ];
            // Outdoor air for sizing only. Given "for control" too, the terminal raises its
            // minimum flow until the zone gets its outdoor air at the AHU's outdoor-air
            // fraction, which with a fixed minimum outdoor-air flow holds every box at its
            // maximum flow all year: the VAV system then runs as constant-volume reheat and
            // the zone set-points move nothing but the sizing (measured, issue 17).
            f.resize(32, String::new());
            f.push("Outdoor Air".into()); // for sizing
            m.add("HVACTemplate:Zone:VAV", &f);
        }
        for ahu in 1..=ahus {
            let mut f = vec![
                format!("AHU{ahu}"),
                "Always On".into(),
                "autosize".into(),
                "autosize".into(),
                "0.7".into(),
                "1000".into(),
                "0.9".into(),
                "1".into(),
                "ChilledWater".into(),
                "".into(),
                format!("AHU{ahu} Supply Air"),
                num(DESIGN_SUPPLY_AIR_C),
                "HotWater".into(),
                "".into(),
                format!("AHU{ahu} Preheat"),
                num(DESIGN_SUPPLY_AIR_C - 2.0),
                "".into(),
                "".into(),
                "None".into(),
                "".into(),
                "".into(),
                "".into(),
                "".into(),
                "".into(),
                "autosize".into(),
                "autosize".into(),
                "FixedMinimum".into(),
                "Outdoor Air Fraction".into(),
                if self.economizer {
                    "DifferentialDryBulb"
                } else {
                    "NoEconomizer"
                }
                .into(),
            ];
            f.resize(38, String::new());
            f.push("StayOff".into()); // night cycle: the AHUs run around the clock anyway
            m.add("HVACTemplate:System:VAV", &f);
        }
    }

    /// One four-pipe fan coil per zone (cycling with the load, its outdoor air from the AHU's
    /// dedicated outdoor-air system) and the dedicated outdoor-air systems, their coils on the
    /// supply-air and preheat schedules (the same parameters as the VAV AHUs').
    fn add_doas_fan_coils(&self, m: &mut Idf) {
        for (i, z) in self.zone_names().iter().enumerate() {
            let ahu = self.ahu_of_zone(i);
            let mut f: Vec<String> = vec![
                z.clone(),
                "Thermostat".into(),
                "autosize".into(),
                "".into(),
                "".into(),
                "DetailedSpecification".into(),
            ];
            f.resize(10, String::new());
            f.extend(["", "", "", "", "ChilledWater", ""].map(String::from));
            f.push(num(DESIGN_SUPPLY_AIR_C));
            f.extend(["HotWater", "", ""].map(String::from));
            f.push(format!("AHU{ahu}")); // the zone's dedicated outdoor-air system
            f.extend(["", "", "", ""].map(String::from));
            f.push("Outdoor Air".into());
            f.push("".into());
            f.push("CyclingFan".into());
            f.extend(["", "", ""].map(String::from)); // outdoor air: the DOAS's, not a schedule
            f.push("None".into());
            m.add("HVACTemplate:Zone:FanCoil", &f);
        }
        let hr = self.heat_recovery_effectiveness;
        for ahu in 1..=self.ahu_count() {
            let mut f: Vec<String> = vec![
                format!("AHU{ahu}"),
                "DOAS Availability".into(),
                "DirectIntoZone".into(),
                "autosize".into(),
            ];
            f.resize(8, String::new());
            f.extend(["DrawThrough", "ChilledWater", "", "Scheduled"].map(String::from));
            f.push(num(DESIGN_SUPPLY_AIR_C));
            f.push(format!("AHU{ahu} Supply Air"));
            f.resize(21, String::new());
            f.extend(["HotWater", "", "Scheduled", ""].map(String::from));
            f.push(format!("AHU{ahu} Preheat"));
            f.resize(32, String::new());
            if hr > 0.0 {
                f.extend(["Sensible".to_string(), num(hr), "".into(), "Plate".into()]);
            } else {
                f.push("None".into());
            }
            m.add("HVACTemplate:System:DedicatedOutdoorAir", &f);
        }
    }

    /// The plant (HVACTemplate objects): the chilled-water loop on district cooling and the
    /// hot-water loop on a boiler or district heating.
    pub(super) fn add_plant(&self, m: &mut Idf) {
        m.add(
            "HVACTemplate:Plant:ChilledWaterLoop",
            &[
                "Chilled Water Loop".to_string(),
                "".into(),
                "Intermittent".into(),
                "Default".into(),
                "".into(),
                "CHW Setpoint".into(),
                num(DESIGN_CHILLED_WATER_C),
            ],
        );
        m.add(
            "HVACTemplate:Plant:Chiller",
            &[
                "District Cooling",
                "DistrictChilledWater",
                "autosize",
                "",
                "",
                "1",
            ],
        );
        m.add(
            "HVACTemplate:Plant:HotWaterLoop",
            &[
                "Hot Water Loop",
                "",
                "Intermittent",
                "Default",
                "",
                "HW Setpoint",
                "80",
            ],
        );
        match self.heating_source {
            HeatingSource::Boiler => m.add(
                "HVACTemplate:Plant:Boiler",
                &[
                    "Boiler",
                    "HotWaterBoiler",
                    "autosize",
                    "0.85",
                    "NaturalGas",
                    "1",
                ],
            ),
            HeatingSource::District => m.add(
                "HVACTemplate:Plant:Boiler",
                &[
                    "District Heating",
                    "DistrictHotWater",
                    "autosize",
                    "1.0",
                    "",
                    "1",
                ],
            ),
        }
    }

    /// Domestic hot water: a stand-alone mixed tank (`WaterHeater:Mixed`) heated by the spec's
    /// heating source.
    pub(super) fn add_domestic_hot_water(
        &self,
        m: &mut Idf,
        v: &ParameterValues,
    ) -> Result<(), Error> {
        // Domestic hot water: a stand-alone mixed tank, sized so it never saturates.
        let dhw_fuel = match self.heating_source {
            HeatingSource::Boiler => "NaturalGas",
            HeatingSource::District => "DistrictHeatingWater",
        };
        let dhw_flow = value(v, "hot_water_peak_flow")?;
        if dhw_flow < 0.0 {
            return Err(Error::Parameter {
                name: "hot_water_peak_flow".into(),
                message: "must be >= 0".into(),
            });
        }
        // Fields by IDD position (1-based): 1 name, 2 volume, 3 set-point schedule, 4 deadband,
        // 6 control, 7 max capacity, 11 fuel, 12 efficiency, 20-21 ambient, 24/26 loss
        // coefficients, 28 peak use flow, 29 use fraction schedule, 30 cold water schedule.
        let mut f = vec![String::new(); 30];
        for (i, v) in [
            (1, "DHW Heater".to_string()),
            (2, "2.0".into()),
            (3, "DHW Setpoint".into()),
            (4, "2.0".into()),
            (6, "Modulate".into()),
            (7, "600000".into()),
            (8, "0".into()),
            (11, dhw_fuel.into()),
            (12, "0.9".into()),
            (14, "0".into()),
            (17, "0".into()),
            (20, "Schedule".into()),
            (21, "DHW Ambient".into()),
            (24, "2.0".into()),
            (26, "2.0".into()),
            (28, num(dhw_flow)),
            (29, "Occupancy".into()),
            (30, "DHW Mains".into()),
        ] {
            f[i - 1] = v;
        }
        m.add("WaterHeater:Mixed", &f);
        Ok(())
    }
}
