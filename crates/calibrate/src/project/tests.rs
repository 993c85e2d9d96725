use super::*;

fn project(extra: &str) -> Result<Project, String> {
    let text = format!(
        "model = \"m.toml\"\nweather = \"w.epw\"\n[meters]\nfile = \"meters.csv\"\n{extra}"
    );
    let p: Project = bemcal_energyplus::parse_toml(&text, Path::new("project.toml"))
        .map_err(|e| e.to_string())?;
    p.validate().map(|_| p)
}

/// A generated model from a building spec file (no EnergyPlus needed).
fn spec_model(path: &Path) -> bemcal_energyplus::Model {
    let text = std::fs::read_to_string(path).unwrap();
    let spec =
        bemcal_energyplus::BuildingSpec::from_toml(&text, path).unwrap_or_else(|e| panic!("{e}"));
    let mut m = bemcal_energyplus::Model::generated(spec);
    m.path = path.into();
    m
}

#[test]
fn the_shipped_example_projects_load() {
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    for name in [
        "office/project.toml",
        "office/quick.toml",
        "rsf/project.toml",
    ] {
        let p = Project::load(&examples.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        let model = p.resolve(&p.model);
        assert!(model.is_file(), "{name}: model {:?}", p.model);
        p.check_model(&spec_model(&model), &bemcal_energyplus::idd::Idd::parse(""))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
    }
}

/// Where `value` breaks `schema` (a node of the schema `root`), by keys: a key the schema
/// does not allow (`additionalProperties: false`, from `deny_unknown_fields`), a required
/// key missing, a value of another type or outside an `enum` / `const`; each error is the
/// key path `at` and what is wrong. Follows `$ref`, `anyOf` / `oneOf` (one branch must
/// pass), `allOf`, `properties`, `additionalProperties` and `items`.
fn schema_errors(
    root: &serde_json::Value,
    schema: &serde_json::Value,
    value: &serde_json::Value,
    at: &str,
) -> Vec<String> {
    use serde_json::Value;
    let mut errors = vec![];
    if let Some(r) = schema.get("$ref").and_then(Value::as_str) {
        let name = r.strip_prefix("#/$defs/").expect("a local $ref");
        errors.extend(schema_errors(root, &root["$defs"][name], value, at));
    }
    for key in ["anyOf", "oneOf"] {
        if let Some(branches) = schema.get(key).and_then(Value::as_array) {
            let tried: Vec<Vec<String>> = (branches.iter())
                .map(|b| schema_errors(root, b, value, at))
                .collect();
            if !tried.iter().any(Vec::is_empty) {
                let fewest = tried.into_iter().min_by_key(Vec::len).unwrap_or_default();
                errors.push(format!("{at}: no branch of {key} fits: {fewest:?}"));
            }
        }
    }
    for b in schema
        .get("allOf")
        .and_then(Value::as_array)
        .into_iter()
        .flatten()
    {
        errors.extend(schema_errors(root, b, value, at));
    }
    if let Some(types) = schema.get("type") {
        let fits = |t: &Value| match t.as_str() {
            Some("object") => value.is_object(),
            Some("array") => value.is_array(),
            Some("string") => value.is_string(),
            Some("boolean") => value.is_boolean(),
            Some("integer") => value.is_i64() || value.is_u64(),
            Some("number") => value.is_number(),
            Some("null") => value.is_null(),
            _ => false,
        };
        let fit = match types {
            Value::Array(ts) => ts.iter().any(fits),
            t => fits(t),
        };
        if !fit {
            errors.push(format!("{at}: {value} is not of type {types}"));
            return errors;
        }
    }
    if let Some(names) = schema.get("enum").and_then(Value::as_array) {
        if !names.contains(value) {
            errors.push(format!("{at}: {value} is none of {names:?}"));
        }
    }
    if let Some(c) = schema.get("const") {
        if c != value {
            errors.push(format!("{at}: {value} is not {c}"));
        }
    }
    match value {
        Value::Object(table) => {
            let properties = schema.get("properties").and_then(Value::as_object);
            for required in schema
                .get("required")
                .and_then(Value::as_array)
                .into_iter()
                .flatten()
            {
                let name = required.as_str().unwrap();
                if !table.contains_key(name) {
                    errors.push(format!("{at}: required key {name} missing"));
                }
            }
            for (k, v) in table {
                let path = if at.is_empty() {
                    k.clone()
                } else {
                    format!("{at}.{k}")
                };
                match (
                    properties.and_then(|p| p.get(k)),
                    schema.get("additionalProperties"),
                ) {
                    (Some(sub), _) => errors.extend(schema_errors(root, sub, v, &path)),
                    (None, Some(Value::Bool(false))) => {
                        errors.push(format!("{path}: a key the schema does not allow"))
                    }
                    (None, Some(sub @ Value::Object(_))) => {
                        errors.extend(schema_errors(root, sub, v, &path))
                    }
                    _ => {}
                }
            }
        }
        Value::Array(items) => {
            if let Some(sub) = schema.get("items") {
                for (i, v) in items.iter().enumerate() {
                    errors.extend(schema_errors(root, sub, v, &format!("{at}[{i}]")));
                }
            }
        }
        _ => {}
    }
    errors
}

/// The errors of the project file `text` against [`project_schema`].
fn project_schema_errors(text: &str) -> Vec<String> {
    let schema = serde_json::to_value(project_schema()).unwrap();
    let toml: toml::Value = toml::from_str(text).unwrap();
    let value = serde_json::to_value(toml).unwrap();
    schema_errors(&schema, &schema, &value, "")
}

#[test]
fn the_shipped_example_projects_fit_the_project_schema() {
    let examples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
    for name in [
        "office/project.toml",
        "office/quick.toml",
        "rsf/project.toml",
        "own-idf/project.toml",
    ] {
        let text = std::fs::read_to_string(examples.join(name)).unwrap();
        let errors = project_schema_errors(&text);
        assert!(errors.is_empty(), "{name}: {errors:#?}");
    }
    let schema = serde_json::to_value(project_schema()).unwrap();
    assert_eq!(schema["title"], "bemcal project file");
    assert_eq!(schema["additionalProperties"], false);
    // The check fails where the loader does: a misspelt key, a value of no enum, a
    // required key missing; and passes the hand-written forms.
    let base = "model = \"m.toml\"\nweather = \"w.epw\"\n[meters]\nfile = \"m.csv\"\n";
    for (extra, error) in [
        (
            "[mcmc]\nchain = 4\n",
            "mcmc.chain: a key the schema does not allow",
        ),
        (
            "[mcmc]\nkernel = \"nuts\"\n",
            "mcmc.kernel: no branch of oneOf fits",
        ),
        (
            "[[meters.columns]]\ncolumn = \"h\"\nrole = \"heating\"\nunits = \"kW\"\n",
            "meters.columns[0].units: a key the schema does not allow",
        ),
        (
            "[simulation]\ntimeout = 30\n",
            "simulation.timeout: a key the schema does not allow",
        ),
        (
            "[mcmc]\ntemperature = \"hot\"\n",
            "mcmc.temperature: no branch of anyOf fits",
        ),
        (
            "[validation]\nerror_model = { heating_kwh = \"hourly\" }\n",
            "validation.error_model: no branch of anyOf fits",
        ),
    ] {
        let errors = project_schema_errors(&format!("{base}{extra}"));
        assert!(
            errors.iter().any(|e| e.starts_with(error)),
            "{extra}: {errors:#?}"
        );
        assert!(project(extra).is_err(), "{extra}");
    }
    let errors = project_schema_errors("weather = \"w.epw\"\n[meters]\n");
    assert!(
        errors
            .iter()
            .any(|e| e.contains("required key model missing")),
        "{errors:?}"
    );
    for extra in [
        "[mcmc]\ntemperature = 20\n",
        "[mcmc]\ntemperature = \"surrogate_error\"\n",
        "[validation]\nerror_model = \"level\"\nholdout = [\"oct\", \"nov\"]\n",
        "[validation]\nerror_model = { default = \"auto\", heating_kwh = \"hour_of_day\" }\n",
        "[measured_weather]\ncsv = \"w.csv\"\ntime_zone = \"America/Denver\"\nyear = \"2017-04\"\ncolumns = [{ column = \"p\", field = \"pressure\", unit = \"mbar\" }]\n",
        "[surrogate]\ntime_features = \"hour\"\nlr_schedule = \"cosine\"\n",
    ] {
        let errors = project_schema_errors(&format!("{base}{extra}"));
        assert!(errors.is_empty(), "{extra}: {errors:#?}");
        project(extra).unwrap_or_else(|e| panic!("{extra}: {e}"));
    }
}

/// `check_model` of a project made of `top` (top-level keys and tables before `[meters]`)
/// and `columns` (the meter columns' roles) against `examples/office/small.toml`; the
/// error with the temporary folder written as `DIR`.
fn check(top: &str, roles: &[&str], tail: &str) -> Result<(), String> {
    let dir = tempfile::tempdir().unwrap();
    let mut text = format!(
        "model = \"model.toml\"\nweather = \"w.epw\"\n{top}[meters]\nfile = \"meters.csv\"\n"
    );
    for r in roles {
        text.push_str(&format!(
            "[[meters.columns]]\ncolumn = \"{r} (kWh)\"\nrole = \"{r}\"\nunit = \"kWh\"\n"
        ));
    }
    text.push_str(tail);
    let path = dir.path().join("project.toml");
    std::fs::write(&path, text).unwrap();
    let model = dir.path().join("model.toml");
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/office/small.toml"),
        &model,
    )
    .unwrap();
    Project::load(&path)
        .and_then(|p| p.check_model(&spec_model(&model), &bemcal_energyplus::idd::Idd::parse("")))
        .map_err(|e| {
            e.to_string()
                .replace(&dir.path().display().to_string(), "DIR")
        })
}

#[test]
fn fixed_values_outside_the_prior_or_not_finite_are_refused_with_the_range() {
    let hc = ["heating", "cooling", "electricity"];
    check(
        "[fixed]\nshgc = 0.6\nwindow_glass_conductivity = 0.01\n",
        &hc,
        "",
    )
    .unwrap();
    assert_eq!(
        check(
            "[fixed]\nshgc = 0.6\nwindow_glass_conductivity = -1000\n",
            &hc,
            ""
        )
        .unwrap_err(),
        "DIR/project.toml:5: [fixed] window_glass_conductivity = -1000.0 is outside \
         0.01..0.02 W/m-K, the range of its prior in DIR/model.toml (a value outside it \
         needs a wider prior there)"
    );
    assert_eq!(
        check("[fixed]\nshgc = 0.81\n", &hc, "").unwrap_err(),
        "DIR/project.toml:4: [fixed] shgc = 0.81 is outside 0.3..0.8, the range of its \
         prior in DIR/model.toml (a value outside it needs a wider prior there)"
    );
    for v in ["inf", "-inf", "nan"] {
        let e = check(&format!("[fixed]\nshgc = {v}\n"), &hc, "").unwrap_err();
        assert!(
            e.starts_with("DIR/project.toml:4: [fixed] shgc = ")
                && e.ends_with(" is not a finite number"),
            "{e}"
        );
    }
    assert!(check("[fixed]\nshgcc = 0.5\n", &hc, "")
        .unwrap_err()
        .starts_with("DIR/project.toml:4: [fixed] shgcc: unknown parameter; the model has: "));
    // Each in its prior, together impossible.
    assert_eq!(
        check(
            "[fixed]\nheating_setpoint_occupied = 23.5\ncooling_setpoint_occupied = 22.0\n",
            &hc,
            ""
        )
        .unwrap_err(),
        "DIR/project.toml:5: [fixed] heating_setpoint_occupied = 23.5 and \
         cooling_setpoint_occupied = 22 violate heating_setpoint_occupied + 0 <= \
         cooling_setpoint_occupied: a heating set-point above the cooling set-point is fatal \
         in EnergyPlus (DualSetPointWithDeadband)"
    );
}

#[test]
fn meter_roles_and_outputs_the_model_cannot_use_are_refused_naming_the_known_ones() {
    let hc = ["heating", "cooling", "electricity"];
    check(
        "[outputs]\nheating_kwh = \"heating\"\nlighting_kwh = \"lighting\"\n",
        &["heating", "lighting"],
        "",
    )
    .unwrap();
    // A misspelt column role: heating would be left out of the calibration.
    assert_eq!(
        check("", &["heatng", "cooling", "electricity"], "").unwrap_err(),
        "DIR/project.toml:7: [[meters.columns]] column = \"heatng (kWh)\": role 'heatng' is \
         compared with no model output and is no [[bases]] submeter (outputs map \
         cooling_kwh = \"cooling\", electricity_kwh = \"electricity\", heating_kwh = \
         \"heating\"; the model's outputs: heating_kwh, cooling_kwh, electricity_kwh, \
         lighting_kwh, equipment_kwh); map an output to it in [outputs] or remove the column"
    );
    // A misspelt role in [outputs].
    assert_eq!(
        check("[outputs]\nheating_kwh = \"heatin\"\n", &hc, "").unwrap_err(),
        "DIR/project.toml:4: [outputs] heating_kwh = \"heatin\": no [[meters.columns]] has \
         role 'heatin' (their roles: heating, cooling, electricity)"
    );
    // An output the model does not have.
    assert_eq!(
        check("[outputs]\ngas_kwh = \"heating\"\n", &hc, "").unwrap_err(),
        "DIR/project.toml:4: [outputs] gas_kwh = \"heating\": the model has no output gas_kwh \
         (it has heating_kwh, cooling_kwh, electricity_kwh, lighting_kwh, equipment_kwh)"
    );
    // A base's sub-meter that no column has, and one that is there.
    let base = "[[bases]]\noutput = \"electricity_kwh\"\nsubmeter = \"server_room\"\n";
    assert_eq!(
        check(base, &["electricity", "data_center"], "").unwrap_err(),
        "DIR/project.toml:5: [[bases]] submeter = \"server_room\": no [[meters.columns]] has \
         role 'server_room' (their roles: electricity, data_center)"
    );
    check(
        &base.replace("server_room", "data_center"),
        &["electricity", "data_center"],
        "",
    )
    .unwrap();
    assert_eq!(
        check(
            &base.replace("electricity_kwh", "gas_kwh"),
            &["electricity", "server_room"],
            ""
        )
        .unwrap_err(),
        "DIR/project.toml:4: [[bases]] output = \"gas_kwh\": the model has no output gas_kwh \
         (it has heating_kwh, cooling_kwh, electricity_kwh, lighting_kwh, equipment_kwh)"
    );
    // Columns detected from the headers are checked once the meters are read.
    check("[outputs]\nheating_kwh = \"heatin\"\n", &[], "").unwrap();
}

#[test]
fn an_error_model_for_every_meter_or_one_per_meter() {
    use bemcal_stats::predictive::ErrorModel;
    use ErrorModelSetting::{Auto, Fixed};
    let models = |extra: &str| project(&format!("[validation]\n{extra}")).unwrap();
    let one = models("error_model = \"hour_of_day\"\n")
        .validation
        .error_model;
    assert_eq!(one.of("heating_kwh"), Fixed(ErrorModel::HourOfDay));
    assert_eq!(project("").unwrap().validation.error_model.of("x"), Auto);
    let each = models("error_model = { heating_kwh = \"hour_of_day\", default = \"constant\" }\n")
        .validation
        .error_model;
    assert_eq!(each.of("heating_kwh"), Fixed(ErrorModel::HourOfDay));
    assert_eq!(each.of("cooling_kwh"), Fixed(ErrorModel::Constant));
    let auto = models("error_model = { default = \"auto\", heating_kwh = \"level\" }\n")
        .validation
        .error_model;
    assert_eq!(auto.of("cooling_kwh"), Auto);
    assert_eq!(auto.of("heating_kwh"), Fixed(ErrorModel::Level));
    assert_eq!(
        serde_json::to_string(&auto).unwrap(),
        r#"{"default":"auto","heating_kwh":"level"}"#
    );
    // Written back as read: a string for one, a table with its default for several.
    assert_eq!(serde_json::to_string(&one).unwrap(), "\"hour_of_day\"");
    assert_eq!(
        serde_json::to_string(&each).unwrap(),
        r#"{"default":"constant","heating_kwh":"hour_of_day"}"#
    );
    let e = project("[validation]\nerror_model = { heating_kwh = \"hourly\" }\n").unwrap_err();
    assert!(e.contains("hourly") && e.contains("hour_of_day"), "{e}");
    // A meter the model does not have.
    let e = check(
        "",
        &[],
        "[validation]\nerror_model = { gas_kwh = \"level\" }\n",
    )
    .unwrap_err();
    assert!(
        e.starts_with(
            "DIR/project.toml:6: [validation] error_model.gas_kwh = \"level\": the model \
             has no output gas_kwh"
        ),
        "{e}"
    );
}

#[test]
fn simulation_limits_default_to_900_s_8_gib_2_gib_and_are_checked() {
    use bemcal_energyplus::confine::Limits;
    let p = project("").unwrap();
    assert_eq!(p.simulation.limits(), Limits::default());
    let p =
        project("[simulation]\ntimeout_s = 30\nmemory_gib = 0.5\nmax_output_gib = 1.5\n").unwrap();
    let l = p.simulation.limits();
    assert_eq!(l.wall, std::time::Duration::from_secs(30));
    assert_eq!(l.memory_bytes, Some(512 << 20));
    assert_eq!(l.output_bytes, Some(3 << 29));
    for (bad, key) in [
        ("timeout_s = 0", "simulation.timeout_s = 0"),
        ("timeout_s = -5", "simulation.timeout_s = -5"),
        ("timeout_s = nan", "simulation.timeout_s = NaN"),
        ("timeout_s = 1e9", "simulation.timeout_s = 1000000000"),
        ("memory_gib = inf", "simulation.memory_gib = inf"),
        ("max_output_gib = 0.0", "simulation.max_output_gib = 0"),
    ] {
        let e = project(&format!("[simulation]\n{bad}\n")).unwrap_err();
        assert!(
            e.contains(key) && e.contains("positive, finite"),
            "{bad}: {e}"
        );
    }
    let e = project("[simulation]\ntimeout = 30\n").unwrap_err();
    assert!(e.contains("unknown field `timeout`"), "{e}");
}

#[test]
fn refinement_settings_default_on_and_are_checked() {
    let p = project("").unwrap();
    assert_eq!((p.refine.rounds, p.refine.iterations), (2, 120));
    let p = project("[refine]\nrounds = 0\n").unwrap();
    assert_eq!(p.refine.rounds, 0);
    let p = project("[refine]\nrounds = 3\npoints = 5\n").unwrap();
    assert_eq!(
        (p.refine.rounds, p.refine.points, p.refine.iterations),
        (3, 5, 120)
    );
    let e = project("[refine]\nrounds = 1\niterations = 500\nburn_in = 500\n").unwrap_err();
    assert!(
        e.contains("refine.burn_in = 500 must be below refine.iterations = 500"),
        "{e}"
    );
    let e = project("[refine]\nrounds = 1\npoints = 0\n").unwrap_err();
    assert!(e.contains("refine.points must be at least 1"), "{e}");
    let e = project("[refine]\nround = 1\n").unwrap_err();
    assert!(e.contains("round"), "{e}");
}

#[test]
fn savings_with_the_calibration_are_off_unless_asked_and_need_measures() {
    let p = project("").unwrap();
    assert!(!p.savings.with_calibration);
    assert_eq!(
        (p.savings.draws, p.savings.split),
        (30, crate::savings::Split::Priors)
    );
    let measure = "[[measures]]\nname = \"LED\"\nscale = { lighting_power_density = 0.6 }\n";
    let p = project(&format!(
        "[savings]\nwith_calibration = true\ndraws = 4\nsplit = \"chains\"\n{measure}"
    ))
    .unwrap();
    assert_eq!(
        (p.savings.draws, p.savings.split),
        (4, crate::savings::Split::Chains)
    );
    let e = project("[savings]\nwith_calibration = true\n").unwrap_err();
    assert!(e.contains("needs [[measures]]"), "{e}");
    let e = project(&format!("[savings]\ndraws = 1\n{measure}")).unwrap_err();
    assert!(
        e.contains("savings.draws = 1: 1 posterior draws for the savings: at least 2"),
        "{e}"
    );
    let e = project("[[measures]]\nname = \"Baseline\"\noffset = { x = 1.0 }\n").unwrap_err();
    assert!(
        e.contains("the name 'baseline' is the runs' without a measure"),
        "{e}"
    );
    let e = project("[savings]\nsplit = \"halves\"\n").unwrap_err();
    assert!(e.contains("halves"), "{e}");
}

#[test]
fn the_temperature_is_one_a_number_at_least_one_or_the_surrogates_error() {
    assert_eq!(
        project("").unwrap().mcmc.temperature,
        Temperature::Fixed(1.0)
    );
    let t = |text: &str| project(&format!("[mcmc]\ntemperature = {text}\n"));
    assert_eq!(t("20").unwrap().mcmc.temperature, Temperature::Fixed(20.0));
    assert_eq!(t("2.5").unwrap().mcmc.temperature, Temperature::Fixed(2.5));
    assert_eq!(
        t("\"surrogate_error\"").unwrap().mcmc.temperature,
        Temperature::SurrogateError
    );
    let e = t("0.5").unwrap_err();
    assert!(
        e.contains("mcmc.temperature = 0.5 must be at least 1"),
        "{e}"
    );
    let e = t("\"surogate_error\"").unwrap_err();
    assert!(
        e.contains(
            "unknown temperature \"surogate_error\": expected a number >= 1 or \"surrogate_error\""
        ),
        "{e}"
    );
    let e = t("true").unwrap_err();
    assert!(
        e.contains("expected a number >= 1 or \"surrogate_error\""),
        "{e}"
    );
    let e =
        project("[mcmc]\ntemperature = \"surrogate_error\"\n[refine]\nrounds = 0\n").unwrap_err();
    assert!(e.contains("needs refine.rounds >= 1"), "{e}");
    let e =
        project("[mcmc]\ntemperature = \"surrogate_error\"\n[refine]\npoints = 1\n").unwrap_err();
    assert!(e.contains("refine.points >= 2"), "{e}");
    // Written back as the project spells it.
    for t in [Temperature::Fixed(2.5), Temperature::SurrogateError] {
        let json = serde_json::to_string(&t).unwrap();
        assert_eq!(
            serde_json::from_str::<Temperature>(&json).unwrap(),
            t,
            "{json}"
        );
    }
}

#[test]
fn the_surrogate_is_the_references_2_x_128_unless_asked() {
    assert_eq!(project("").unwrap().surrogate.hidden, 128);
    assert_eq!(
        project("[surrogate]\nhidden = 32\n")
            .unwrap()
            .surrogate
            .hidden,
        32
    );
    let e = project("[surrogate]\nhidden = 2\n").unwrap_err();
    assert!(
        e.contains("surrogate.hidden = 2 must be between 4 and 1024"),
        "{e}"
    );
}

#[test]
fn the_learning_rate_is_constant_unless_asked() {
    use bemcal_surrogate::LrSchedule;
    assert_eq!(
        project("").unwrap().surrogate.lr_schedule,
        LrSchedule::Constant
    );
    let cosine = project("[surrogate]\nlr_schedule = \"cosine\"\nlr = 3e-3\n").unwrap();
    assert_eq!(cosine.surrogate.lr_schedule, LrSchedule::Cosine);
    assert_eq!(cosine.surrogate.lr, 3e-3);
    let e = project("[surrogate]\nlr = 0\n").unwrap_err();
    assert!(e.contains("surrogate.lr = 0 must be in (0, 1)"), "{e}");
    let e = project("[surrogate]\nlr_schedule = \"step\"\n").unwrap_err();
    assert!(e.contains("lr_schedule") && e.contains("cosine"), "{e}");
}

#[test]
fn the_default_sampler_is_hmc_from_optima_held_to_convergence_targets() {
    let m = project("").unwrap().mcmc;
    assert_eq!((m.kernel, m.start), (Kernel::Hmc, ChainStart::Optimised));
    assert_eq!((m.iterations, m.burn_in), (500, 150));
    assert_eq!(
        (m.rhat_target, m.ess_target, m.max_extensions),
        (1.01, 400.0, 3)
    );
    let m = project("[mcmc]\nkernel = \"mh\"\nstart = \"prior\"\niterations = 10000\n")
        .unwrap()
        .mcmc;
    assert_eq!(
        (m.kernel, m.start, m.iterations),
        (Kernel::Mh, ChainStart::Prior, 10000)
    );
    let e = project("[mcmc]\ness_target = -1\n").unwrap_err();
    assert!(
        e.contains("mcmc.ess_target = -1 must be a number >= 0"),
        "{e}"
    );
    let e = project("[mcmc]\nrhat_target = 0\n").unwrap_err();
    assert!(
        e.contains("mcmc.rhat_target = 0 must be a positive number"),
        "{e}"
    );
}

/// A setting that fails its check is refused at its line, where the message names its key.
#[test]
fn a_failed_check_names_the_line_of_its_key() {
    let hc = ["heating", "cooling", "electricity"];
    let e = check(
        "[surrogate]\nepochs = 3\npretrained = \"bundled:nope\"\n",
        &hc,
        "",
    )
    .unwrap_err();
    assert!(
        e.starts_with(
            "DIR/project.toml:5: surrogate.pretrained: no bundled pretrained network 'nope'"
        ),
        "{e}"
    );
    let e = check("[surrogate]\nhidden = 2\n", &hc, "").unwrap_err();
    assert!(
        e.starts_with("DIR/project.toml:4: surrogate.hidden = 2 "),
        "{e}"
    );
    assert_eq!(super::validate::leading_key("[meters] needs"), None);
    assert_eq!(
        super::validate::leading_key("mcmc.temperature = \"x\""),
        Some(vec!["mcmc", "temperature"])
    );
}
