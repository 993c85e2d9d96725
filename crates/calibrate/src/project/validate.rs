//! The project file's checks: what serde cannot say about one file (ranges, combinations,
//! names that must be unique), then what it must agree on with the model it names (parameters,
//! outputs, meter roles). Every refusal names the file and, where it has one, the key.

use super::*;

/// The key a check's message starts with (`surrogate.hidden = 3 must be ...` gives
/// `["surrogate", "hidden"]`), to find its line; None where it names none.
pub(super) fn leading_key(message: &str) -> Option<Vec<&str>> {
    let end = message
        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == '.'))
        .unwrap_or(message.len());
    let key = &message[..end];
    (key.contains('.') && !key.starts_with('.') && !key.ends_with('.'))
        .then(|| key.split('.').collect())
}

impl Project {
    /// Reads and validates a project file.
    pub fn load(path: &Path) -> Result<Project, Error> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::Input {
            path: path.into(),
            line: 0,
            message: format!("cannot read: {e}"),
        })?;
        let mut p: Project = bemcal_energyplus::parse_toml(&text, path).map_err(Error::from)?;
        p.base = path.parent().unwrap_or(Path::new(".")).to_path_buf();
        p.path = path.to_path_buf();
        p.validate().map_err(|message| Error::Input {
            path: path.into(),
            line: leading_key(&message)
                .map_or(0, |keys| bemcal_energyplus::toml_line(&text, &keys)),
            message,
        })?;
        Ok(p)
    }

    /// Checks settings that serde cannot.
    pub fn validate(&self) -> Result<(), String> {
        if let Some(m) = &self.measured_weather {
            m.validate()?;
        }
        for b in &self.bases {
            b.check()?;
        }
        self.design.check()?;
        self.mcmc.check()?;
        self.refine.check()?;
        if self.mcmc.temperature == Temperature::SurrogateError
            && (self.refine.rounds == 0 || self.refine.points < 2)
        {
            return Err(
                "mcmc.temperature = \"surrogate_error\" needs refine.rounds >= 1 and \
                        refine.points >= 2: the surrogate's error is measured at a refinement \
                        round's points"
                    .into(),
            );
        }
        self.surrogate.check()?;
        self.simulation.check()?;
        let most = crate::keys::FIRST_MAPPED_KEY - crate::keys::FIRST_PREDICTIVE_KEY;
        if self.validation.predictive_draws > most {
            return Err(format!(
                "validation.predictive_draws = {}: at most {most} (each is an EnergyPlus run)",
                self.validation.predictive_draws
            ));
        }
        let mut folders = std::collections::BTreeSet::new();
        for m in &self.measures {
            m.check()?;
            // The runs without a measure have that folder (`savings::run_rel`).
            if m.folder() == "baseline" {
                return Err(format!(
                    "measure '{}': the name 'baseline' is the runs' without a measure: give the \
                     measure another",
                    bemcal_excerpt::excerpt(&m.name, 60)
                ));
            }
            if !folders.insert(m.folder()) {
                return Err(format!(
                    "measure '{}': another measure has the same name (letters and digits, \
                     case aside): give each its own",
                    bemcal_excerpt::excerpt(&m.name, 60)
                ));
            }
        }
        if self.savings.with_calibration && self.measures.is_empty() {
            return Err(
                "[savings] with_calibration = true needs [[measures]] (a name and set, \
                 scale or offset of parameters, or building fields)"
                    .into(),
            );
        }
        crate::savings::check_draws(self.savings.draws)
            .map_err(|e| format!("savings.draws = {}: {e}", self.savings.draws))?;
        if self.meters.file.is_none() && self.meters.bills.is_empty() {
            return Err(
                "[meters] needs file = \"...\" (hourly or sub-hourly meters) or [[meters.bills]] (utility bills)"
                    .into(),
            );
        }
        Ok(())
    }

    /// An error in the project file at the key `keys` (its line, when the file can be read
    /// again and has the key; 0 otherwise, as for a default value).
    pub(crate) fn error_at(&self, keys: &[&str], message: String) -> Error {
        let line = std::fs::read_to_string(&self.path)
            .map_or(0, |text| bemcal_energyplus::toml_line(&text, keys));
        Error::Input {
            path: self.path.clone(),
            line,
            message,
        }
    }

    /// Checks the project against its model before anything runs: `[fixed]` values are known
    /// parameters, finite and inside the support of the parameter's prior as the model declares
    /// it (`model` before a priors file narrows it) and satisfy the model's constraints between
    /// them; `[outputs]` names outputs the model has; and with `[[meters.columns]]` given,
    /// every role that `[outputs]` or a `[[bases]]` sub-meter names is a column's role and
    /// every column's role is compared with a model output or is a base.
    pub fn check_model(
        &self,
        model: &bemcal_energyplus::Model,
        idd: &bemcal_energyplus::idd::Idd,
    ) -> Result<(), Error> {
        self.check_fixed(model)?;
        self.check_measures(model, idd)?;
        let outputs: Vec<&str> = model.outputs().iter().map(|o| o.name.as_str()).collect();
        self.check_outputs(&outputs)?;
        self.check_meter_roles(&outputs)
    }

    /// `[[measures]]`: every parameter a measure edits is the model's, and its building and
    /// IDF edits apply.
    fn check_measures(
        &self,
        model: &bemcal_energyplus::Model,
        idd: &bemcal_energyplus::idd::Idd,
    ) -> Result<(), Error> {
        let all: Vec<String> = model.parameters().iter().map(|p| p.name.clone()).collect();
        for (i, m) in self.measures.iter().enumerate() {
            // The line of the measure itself ([[measures]] number i).
            m.check_model(model, idd, &all, &Default::default())
                .map_err(|message| self.error_at(&["measures", &i.to_string()], message))?;
        }
        Ok(())
    }

    /// `[fixed]`: each a parameter of the model, finite, inside its prior, and together
    /// within the model's constraints.
    fn check_fixed(&self, model: &bemcal_energyplus::Model) -> Result<(), Error> {
        let params = model.parameters();
        let param_names = || {
            params
                .iter()
                .map(|p| p.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        };
        for (name, &v) in &self.fixed {
            let at = |m: String| self.error_at(&["fixed", name], format!("[fixed] {m}"));
            let Some(p) = params.iter().find(|p| &p.name == name) else {
                return Err(at(format!(
                    "{}: unknown parameter; the model has: {}",
                    excerpt(name),
                    param_names()
                )));
            };
            if !v.is_finite() {
                return Err(at(format!("{name} = {v:?} is not a finite number")));
            }
            if !p.prior.contains(v) {
                let unit = match p.unit.as_str() {
                    "" | "-" => String::new(),
                    u => format!(" {u}"),
                };
                return Err(at(format!(
                    "{name} = {v:?} is outside {:?}..{:?}{unit}, the range of its prior in {} \
                     (a value outside it needs a wider prior there)",
                    p.prior.min,
                    p.prior.max,
                    model.path.display()
                )));
            }
        }
        for c in model.constraints() {
            c.check(&self.fixed).map_err(|e| {
                let message = match e {
                    bemcal_energyplus::Error::Parameter { message, .. } => message,
                    e => e.to_string(),
                };
                self.error_at(&["fixed", &c.upper], format!("[fixed] {message}"))
            })?;
        }
        Ok(())
    }

    /// `[outputs]`, `[[bases]]` and `[validation] error_model` name outputs the model has
    /// (`outputs`).
    fn check_outputs(&self, outputs: &[&str]) -> Result<(), Error> {
        let roles = self.output_roles();
        for (name, role) in &roles {
            if !outputs.contains(&name.as_str()) {
                return Err(self.error_at(
                    &["outputs", name],
                    format!(
                        "[outputs] {} = \"{}\": the model has no output {} (it has {})",
                        excerpt(name),
                        excerpt(role),
                        excerpt(name),
                        outputs.join(", ")
                    ),
                ));
            }
        }
        for name in self.validation.error_model.by_output.keys() {
            if !outputs.contains(&name.as_str()) {
                return Err(self.error_at(
                    &["validation", "error_model", name],
                    format!(
                        "[validation] error_model.{} = \"{}\": the model has no output {} (it \
                         has {}; `default` sets the others')",
                        excerpt(name),
                        self.validation.error_model.of(name).as_str(),
                        excerpt(name),
                        outputs.join(", ")
                    ),
                ));
            }
        }
        for (i, b) in self.bases.iter().enumerate() {
            if !outputs.contains(&b.output.as_str()) {
                return Err(self.error_at(
                    &["bases", &i.to_string(), "output"],
                    format!(
                        "[[bases]] output = \"{}\": the model has no output {} (it has {})",
                        excerpt(&b.output),
                        excerpt(&b.output),
                        outputs.join(", ")
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The meters' columns against the outputs and bases: every output's role and every
    /// base's submeter has a column, every column is used, one column per role, and
    /// `fit = false` only on a compared meter. Roles are known only when the
    /// columns are listed (otherwise they are detected from the CSV's headers, checked once it
    /// is read).
    fn check_meter_roles(&self, outputs: &[&str]) -> Result<(), Error> {
        if self.meters.columns.is_empty() {
            return Ok(());
        }
        self.check_roles_have_columns()?;
        self.check_columns_are_used(outputs)
    }

    /// Every `[outputs]` role and every base's submeter has a column.
    fn check_roles_have_columns(&self) -> Result<(), Error> {
        use bemcal_precal::meters::MeterRole;
        let columns = &self.meters.columns;
        let column_roles = || {
            let mut r: Vec<&str> = vec![];
            for c in columns {
                if !r.contains(&c.role.name()) {
                    r.push(c.role.name());
                }
            }
            r.join(", ")
        };
        let has_column = |role: &MeterRole| columns.iter().any(|c| &c.role == role);
        for (name, role) in &self.outputs {
            if !has_column(&MeterRole::from(role.clone())) {
                return Err(self.error_at(
                    &["outputs", name],
                    format!(
                        "[outputs] {} = \"{}\": no [[meters.columns]] has role '{}' \
                         (their roles: {})",
                        excerpt(name),
                        excerpt(role),
                        excerpt(role),
                        column_roles()
                    ),
                ));
            }
        }
        for (i, b) in self.bases.iter().enumerate() {
            if let Some(sub) = &b.submeter {
                if !has_column(&MeterRole::from(sub.clone())) {
                    return Err(self.error_at(
                        &["bases", &i.to_string(), "submeter"],
                        format!(
                            "[[bases]] submeter = \"{}\": no [[meters.columns]] has role \
                             '{}' (their roles: {})",
                            excerpt(sub),
                            excerpt(sub),
                            column_roles()
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Every column is compared with a model output or is a base's submeter, one column per
    /// role, and `fit = false` only on a compared meter.
    fn check_columns_are_used(&self, outputs: &[&str]) -> Result<(), Error> {
        use bemcal_precal::meters::MeterRole;
        let roles = self.output_roles();
        let columns = &self.meters.columns;
        // A column whose role no model output is compared with and no base uses would be read
        // and then ignored: a misspelt `heatng` left heating out of the calibration unnoticed.
        let compared: Vec<MeterRole> = roles.values().cloned().map(MeterRole::from).collect();
        let used: Vec<MeterRole> = compared
            .iter()
            .cloned()
            .chain(
                self.bases
                    .iter()
                    .filter_map(|b| b.submeter.clone().map(MeterRole::from)),
            )
            .collect();
        for (i, c) in columns.iter().enumerate() {
            if !used.contains(&c.role) {
                let mapped: Vec<String> = roles
                    .iter()
                    .map(|(o, r)| format!("{o} = \"{r}\""))
                    .collect();
                return Err(self.error_at(
                    &["meters", "columns", &i.to_string(), "role"],
                    format!(
                        "[[meters.columns]] column = \"{}\": role '{}' is compared with no model \
                         output and is no [[bases]] submeter (outputs map {}; the model's outputs: \
                         {}); map an output to it in [outputs] or remove the column",
                        excerpt(&c.column),
                        excerpt(c.role.name()),
                        mapped.join(", "),
                        outputs.join(", ")
                    ),
                ));
            }
        }
        // One column per role (the meters keep the first column of a role: a second would be
        // read and ignored), and `fit = false` only on a meter the model is compared with (a
        // `[[bases]]` submeter is never fitted).
        for (i, c) in columns.iter().enumerate() {
            if let Some(first) = columns[..i].iter().find(|o| o.role == c.role) {
                return Err(self.error_at(
                    &["meters", "columns", &i.to_string(), "role"],
                    format!(
                        "[[meters.columns]] column = \"{}\" has role '{}', as column = \"{}\" \
                         before it: one column per role (give the same column another role to \
                         use it twice)",
                        excerpt(&c.column),
                        excerpt(c.role.name()),
                        excerpt(&first.column)
                    ),
                ));
            }
            if !c.fit && !compared.contains(&c.role) {
                return Err(self.error_at(
                    &["meters", "columns", &i.to_string(), "fit"],
                    format!(
                        "[[meters.columns]] column = \"{}\": fit = false on role '{}', which no \
                         model output is compared with (a [[bases]] submeter is never fitted); \
                         remove fit = false",
                        excerpt(&c.column),
                        excerpt(c.role.name())
                    ),
                ));
            }
        }
        Ok(())
    }
}

impl Base {
    /// A base gives either a sub-meter or a constant load >= 0.
    pub fn check(&self) -> Result<(), String> {
        match (&self.submeter, self.kwh_per_hour) {
            (Some(_), None) => {}
            (None, Some(v)) if v.is_finite() && v >= 0.0 => {}
            (None, Some(v)) => {
                return Err(format!(
                    "[[bases]] output = \"{}\": kwh_per_hour = {v}, expected a load >= 0",
                    self.output
                ))
            }
            _ => {
                return Err(format!(
                    "[[bases]] output = \"{}\": give submeter = \"NAME\" or kwh_per_hour = NUMBER (one of them)",
                    self.output
                ))
            }
        }
        Ok(())
    }
}

impl DesignSettings {
    /// Checks the `[design]` settings.
    pub fn check(&self) -> Result<(), String> {
        if self.points < 3 {
            return Err(format!("design.points = {}, need at least 3", self.points));
        }
        if self.parallel == 0 {
            return Err("design.parallel must be at least 1".into());
        }
        if !(self.min_success > 0.0 && self.min_success <= 1.0) {
            return Err(format!(
                "design.min_success = {}: expected a share in (0, 1], such as 0.8",
                self.min_success
            ));
        }
        Ok(())
    }
}

impl McmcSettings {
    /// Checks the `[mcmc]` settings.
    pub fn check(&self) -> Result<(), String> {
        if self.chains == 0 {
            return Err("mcmc.chains must be at least 1".into());
        }
        if self.burn_in >= self.iterations {
            return Err(format!(
                "mcmc.burn_in = {} must be below mcmc.iterations = {}",
                self.burn_in, self.iterations
            ));
        }
        if self.residuals == Residuals::Ar1 && self.sigma_delta != SigmaDeltaMode::Marginal {
            return Err("mcmc.residuals = \"ar1\" needs mcmc.sigma_delta = \"marginal\"".into());
        }
        if self.discrepancy != DiscrepancyTerm::None && self.sigma_delta != SigmaDeltaMode::Marginal
        {
            return Err(
                "mcmc.discrepancy (a model-form term) needs mcmc.sigma_delta = \"marginal\"".into(),
            );
        }
        if self.segment == 0 {
            return Err("mcmc.segment must be at least 1".into());
        }
        if !(0.0..1.0).contains(&self.independence) {
            return Err(format!(
                "mcmc.independence = {} must be in [0, 1)",
                self.independence
            ));
        }
        if self.kernel == Kernel::Hmc && self.sigma_delta == SigmaDeltaMode::Sampled {
            return Err(
                "mcmc.kernel = \"hmc\" needs mcmc.sigma_delta = \"marginal\" or \"fixed\" \
                 (sampled sigma_delta coordinates have no gradient through the surrogate)"
                    .into(),
            );
        }
        if let Temperature::Fixed(t) = self.temperature {
            if !(t.is_finite() && t >= 1.0) {
                return Err(format!("mcmc.temperature = {t} must be at least 1"));
            }
        }
        if !(self.hmc_integration_time.is_finite() && self.hmc_integration_time > 0.0) {
            return Err(format!(
                "mcmc.hmc_integration_time = {} must be positive",
                self.hmc_integration_time
            ));
        }
        let t = self.rhat_target;
        if !(t.is_finite() && t > 0.0) {
            return Err(format!("mcmc.rhat_target = {t} must be a positive number"));
        }
        let e = self.ess_target;
        if !(e.is_finite() && e >= 0.0) {
            return Err(format!("mcmc.ess_target = {e} must be a number >= 0"));
        }
        if self.restart_below.is_nan() || self.restart_below < 0.0 {
            return Err(format!(
                "mcmc.restart_below = {} must be a number of nats >= 0",
                self.restart_below
            ));
        }
        Ok(())
    }
}

impl RefineSettings {
    /// Checks the `[refine]` settings (only when there are rounds).
    pub fn check(&self) -> Result<(), String> {
        if self.rounds > 0 {
            if self.points == 0 {
                return Err("refine.points must be at least 1 when refine.rounds > 0".into());
            }
            let f = self.spread;
            if !(1.0..=20.0).contains(&f) {
                return Err(format!(
                    "refine.spread = {f} must be between 1 (the draws themselves) and 20"
                ));
            }
            if self.burn_in >= self.iterations {
                return Err(format!(
                    "refine.burn_in = {} must be below refine.iterations = {}",
                    self.burn_in, self.iterations
                ));
            }
        }
        Ok(())
    }
}

impl SurrogateSettings {
    /// Checks the `[surrogate]` settings.
    pub fn check(&self) -> Result<(), String> {
        if !(0.0..1.0).contains(&self.held_out_fraction) || self.held_out_fraction == 0.0 {
            return Err("surrogate.held_out_fraction must be in (0, 1)".into());
        }
        if !(self.lr > 0.0 && self.lr < 1.0) {
            return Err(format!(
                "surrogate.lr = {} must be in (0, 1) (Adam's learning rate, e.g. 1e-3)",
                self.lr
            ));
        }
        if !(4..=1024).contains(&self.hidden) {
            return Err(format!(
                "surrogate.hidden = {} must be between 4 and 1024 (units per LSTM layer)",
                self.hidden
            ));
        }
        self.time_features
            .parse::<bemcal_surrogate::TimeFeatures>()
            .map_err(|e| format!("surrogate.time_features: {e}"))?;
        if let Some(Err(e)) = self
            .pretrained
            .as_deref()
            .and_then(bemcal_surrogate::pretrained::bundled_name)
        {
            return Err(format!("surrogate.pretrained: {e}"));
        }
        Ok(())
    }
}
