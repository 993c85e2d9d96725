//! Running EnergyPlus: one directory per run, a time limit, `eplusout.err` checked.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::confine::{confine, Limits, Sandbox};
use crate::engine::Engine;
use crate::errfile::{Class, ErrFile};
use crate::idd::Idd;
use crate::idf::Idf;
use crate::meters::{read_meter_csv, HourlyOutputs, OutputSpec};
use crate::{io_err, Error};

/// How a run is carried out.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Limits of one EnergyPlus process: wall time, memory, output size (a run past one is a
    /// failed simulation with that reason).
    pub limits: Limits,
    /// Set the water-coil controllers' convergence tolerance to 0.1 K (the expanded templates
    /// autosize it): about 20 % faster, annual totals within 0.05 % (measured on the example
    /// building, docs/benchmarks.md). The coils keep the templates' `DetailedAnalysis`:
    /// `SimpleAnalysis` was another 4 % faster but moved cooling by 1.6 %, and its design-UA
    /// calculation found no root when the design inlet air's dew point lay just above the
    /// chilled water's temperature (issue 17: 4 of 24 runs of a perimeter + core building at
    /// Golden refused).
    pub fast_coils: bool,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            limits: Limits::default(),
            fast_coils: true,
        }
    }
}

/// Runs simulations. Cheap to clone; safe to use from many threads at once because every run
/// has its own directory and its own copies of its inputs.
#[derive(Debug, Clone)]
pub struct Runner {
    engine: Engine,
    idd: Arc<Idd>,
    options: RunOptions,
    sandbox: Sandbox,
}

/// What one run produced.
#[derive(Debug, Clone)]
pub struct RunResult {
    /// The hourly outputs, kWh.
    pub outputs: HourlyOutputs,
    /// The run's folder.
    pub dir: PathBuf,
    /// Wall time of the run, s.
    pub seconds: f64,
    /// Warning count from `eplusout.err`.
    pub warnings: usize,
    /// Severe messages after which the results are still usable (see
    /// [`crate::errfile::classify`]): the message's first line and why it was accepted.
    pub notes: Vec<String>,
}

impl Runner {
    /// A runner for an engine.
    pub fn new(engine: Engine, options: RunOptions) -> Result<Runner, Error> {
        let idd = Idd::read(&engine.idd())?;
        Ok(Runner {
            engine,
            idd: Arc::new(idd),
            options,
            sandbox: Sandbox::probe(),
        })
    }

    /// The isolation EnergyPlus runs under on this host.
    pub fn sandbox(&self) -> Sandbox {
        self.sandbox
    }

    /// The same runner with other limits (a project's `[simulation]` settings).
    pub fn with_limits(&self, limits: Limits) -> Runner {
        let mut r = self.clone();
        r.options.limits = limits;
        r
    }

    /// The limits of each EnergyPlus process.
    pub fn limits(&self) -> &Limits {
        &self.options.limits
    }

    /// The engine.
    pub fn engine(&self) -> &Engine {
        &self.engine
    }

    /// The data dictionary.
    pub fn idd(&self) -> &Idd {
        &self.idd
    }

    /// The IDF EnergyPlus is given for `idf`: HVAC templates expanded (ExpandObjects runs in
    /// `dir`) and, with [`RunOptions::fast_coils`], the water-coil controllers' coarser
    /// tolerance. This is the model as simulated, runnable with `energyplus -w EPW` and nothing
    /// else.
    pub fn simulated_input(&self, idf: &Idf, dir: &Path) -> Result<Idf, Error> {
        std::fs::create_dir_all(dir).map_err(io_err(dir))?;
        let mut model = idf.clone();
        if model.has_class_prefix("HVACTemplate:") {
            model = self.expand(&model, dir)?;
        }
        if self.options.fast_coils {
            self.speed_up_coils(&mut model);
        }
        Ok(model)
    }

    /// Runs `idf` with `weather` in `dir` (created; must not hold an earlier run) and reads the
    /// hourly `outputs`.
    pub fn run(
        &self,
        idf: &Idf,
        weather: &Path,
        outputs: &[OutputSpec],
        dir: &Path,
    ) -> Result<RunResult, Error> {
        let t0 = Instant::now();
        if dir.join("eplusout.err").exists() {
            return Err(Error::Simulation {
                dir: dir.into(),
                message: "the run directory already holds a run; every run needs its own".into(),
                details: vec![],
            });
        }
        std::fs::create_dir_all(dir).map_err(io_err(dir))?;
        std::fs::copy(weather, dir.join("in.epw")).map_err(io_err(weather))?;
        let model = self.simulated_input(idf, dir)?;
        let input = dir.join("model.idf");
        // The exact input, after every edit bemcal applied, is screened once more.
        crate::screen::screen(&model, &self.idd, &input)?;
        std::fs::write(&input, model.to_text()).map_err(io_err(&input))?;
        let mut cmd = bemcal_pyenv::child_command(&self.engine.executable);
        cmd.args(["-w", "in.epw", "-d", "."])
            .arg("model.idf")
            .stdin(Stdio::null());
        confine(&mut cmd, dir, &self.options.limits, self.sandbox);
        let status = run_with_timeout(cmd, dir, &self.options.limits)?;
        let err = read_err_file(dir)?;
        let mut notes = vec![];
        let mut bad: Vec<String> = vec![];
        let mut fatal = false;
        for (m, class) in err.classified() {
            match class {
                Class::Usable { reason } => notes.push(format!("{} ({reason})", m.lines[0])),
                Class::Fatal => {
                    fatal = true;
                    bad.extend(m.lines.iter().cloned());
                }
                Class::Invalidating => bad.extend(m.lines.iter().cloned()),
            }
        }
        if !bad.is_empty() {
            let what = if fatal {
                "EnergyPlus stopped"
            } else {
                "results invalid"
            };
            return Err(Error::Simulation {
                dir: dir.into(),
                message: format!(
                    "{what}: {} severe/fatal message(s) in eplusout.err (exit code {status})",
                    err.problems.len() - notes.len()
                ),
                details: bad.into_iter().take(12).collect(),
            });
        }
        if status != 0 || !err.completed {
            return Err(Error::Simulation {
                dir: dir.into(),
                message: format!("EnergyPlus exit code {status}, did not complete successfully"),
                details: err.tail,
            });
        }
        let csv = dir.join("eplusmtr.csv");
        if !csv.exists() {
            return Err(Error::Simulation {
                dir: dir.into(),
                message: "no eplusmtr.csv written (no hourly Output:Meter in the model?)".into(),
                details: err.tail,
            });
        }
        let outputs = read_meter_csv(&csv, outputs)?;
        Ok(RunResult {
            outputs,
            dir: dir.into(),
            seconds: t0.elapsed().as_secs_f64(),
            warnings: err.warnings,
            notes,
        })
    }

    /// Expands HVACTemplate objects with the engine's ExpandObjects, in `dir`.
    fn expand(&self, model: &Idf, dir: &Path) -> Result<Idf, Error> {
        let xdir = dir.join("expand");
        std::fs::create_dir_all(&xdir).map_err(io_err(&xdir))?;
        std::fs::write(xdir.join("in.idf"), model.to_text()).map_err(io_err(&xdir))?;
        let idd = xdir.join("Energy+.idd");
        if std::os::unix::fs::symlink(self.engine.idd(), &idd).is_err() {
            std::fs::copy(self.engine.idd(), &idd).map_err(io_err(&idd))?;
        }
        let mut cmd = bemcal_pyenv::child_command(self.engine.expand_objects());
        cmd.stdin(Stdio::null());
        let limits = Limits {
            wall: Duration::from_secs(120).min(self.options.limits.wall),
            ..self.options.limits
        };
        confine(&mut cmd, &xdir, &limits, self.sandbox);
        let status = run_with_timeout(cmd, &xdir, &limits)?;
        let out = xdir.join("expanded.idf");
        if status != 0 || !out.exists() {
            let msg = std::fs::read_to_string(xdir.join("expandedidf.err")).unwrap_or_default();
            return Err(Error::Simulation {
                dir: xdir,
                message: format!("ExpandObjects failed (exit code {status})"),
                details: msg.lines().take(12).map(String::from).collect(),
            });
        }
        let text = std::fs::read_to_string(&out).map_err(io_err(&out))?;
        Idf::parse(&text, &out)
    }

    fn speed_up_coils(&self, model: &mut Idf) {
        // IDD indices count the name as field 0, as `fields` does.
        let Some(i) = self
            .idd
            .field_index("Controller:WaterCoil", "Controller Convergence Tolerance")
        else {
            return;
        };
        for o in &mut model.objects {
            if o.class.eq_ignore_ascii_case("Controller:WaterCoil") {
                if o.fields.len() <= i {
                    o.fields.resize(i + 1, String::new());
                }
                o.fields[i] = "0.1".into();
            }
        }
    }
}

fn run_with_timeout(mut cmd: Command, dir: &Path, limits: &Limits) -> Result<i32, Error> {
    let log = dir.join("stdout.log");
    let file = std::fs::File::create(&log).map_err(io_err(&log))?;
    let file2 = file.try_clone().map_err(io_err(&log))?;
    let mut child = cmd
        .stdout(file)
        .stderr(file2)
        .spawn()
        .map_err(|e| Error::Simulation {
            dir: dir.into(),
            message: format!("cannot start {:?}: {e}", cmd.get_program()),
            details: vec![],
        })?;
    let start = Instant::now();
    loop {
        match child.try_wait().map_err(io_err(dir))? {
            Some(status) => {
                use std::os::unix::process::ExitStatusExt;
                if let Some(signal) = status.signal() {
                    return Err(Error::Limit {
                        dir: dir.into(),
                        message: crate::confine::signal_reason(signal, limits),
                    });
                }
                return Ok(status.code().unwrap_or(-1));
            }
            None if start.elapsed() > limits.wall => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(Error::Timeout {
                    dir: dir.into(),
                    seconds: limits.wall.as_secs_f64(),
                });
            }
            None => std::thread::sleep(Duration::from_millis(20)),
        }
    }
}

/// Reads `eplusout.err`: `** Severe` / `** Fatal` lines with their `**   ~~~` continuations.
fn read_err_file(dir: &Path) -> Result<ErrFile, Error> {
    let path = dir.join("eplusout.err");
    let text = std::fs::read_to_string(&path).map_err(|e| Error::Simulation {
        dir: dir.into(),
        message: format!("no eplusout.err ({e}); EnergyPlus did not run"),
        details: std::fs::read_to_string(dir.join("stdout.log"))
            .unwrap_or_default()
            .lines()
            .rev()
            .take(8)
            .map(String::from)
            .collect(),
    })?;
    Ok(ErrFile::parse(&text))
}
