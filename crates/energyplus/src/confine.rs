//! How bemcal starts EnergyPlus and its tools: as untrusted code, with a cleared environment,
//! in the run folder, under limits on wall time, memory and output size, and in a network
//! namespace of its own where the host allows one.
//!
//! The environment is cleared because a model's code objects (refused by [`crate::screen`],
//! but a screen is one line of defence) would otherwise read the worker's secrets
//! (`BEMCAL_TOKEN`): the child gets only `PATH`, `LANG`, and `HOME` and `TMPDIR` set to the run
//! folder. Limits are per process kind: an address-space limit suits EnergyPlus, not PyTorch
//! (whose trainer reserves far more address space than it uses), so the trainer gets none.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

/// The limits of one EnergyPlus (or ExpandObjects) process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Wall-clock limit.
    pub wall: Duration,
    /// Address-space limit, bytes (`RLIMIT_AS`); `None`: unlimited.
    pub memory_bytes: Option<u64>,
    /// Largest file it may write, bytes (`RLIMIT_FSIZE`); `None`: unlimited.
    pub output_bytes: Option<u64>,
}

impl Default for Limits {
    /// 900 s, 8 GiB of address space, 2 GiB per output file. The example's 20-zone building
    /// writes about 30 MB and maps under 1 GiB.
    fn default() -> Self {
        Limits {
            wall: Duration::from_secs(900),
            memory_bytes: Some(8 << 30),
            output_bytes: Some(2 << 30),
        }
    }
}

/// The isolation the host gave EnergyPlus, found once per runner.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sandbox {
    /// A network namespace of its own (no network at all), besides the cleared environment
    /// and the limits.
    NetworkNamespace,
    /// The cleared environment and the limits only: the host refused a namespace.
    None,
}

impl Sandbox {
    /// Tries a network namespace for a short process (`/bin/true`).
    pub fn probe() -> Sandbox {
        let mut cmd = Command::new("/bin/true");
        apply_namespace(&mut cmd);
        match cmd.status() {
            Ok(s) if s.success() => Sandbox::NetworkNamespace,
            _ => Sandbox::None,
        }
    }

    /// In words, for `bemcal doctor` and the logs.
    pub fn describe(self) -> &'static str {
        match self {
            Sandbox::NetworkNamespace => {
                "cleared environment, limits, own network namespace (no network)"
            }
            Sandbox::None => {
                "cleared environment and limits only (the host allows no network namespace)"
            }
        }
    }
}

/// Environment variables a confined process gets (everything else is cleared).
pub const KEPT_PATH: &str = "/usr/local/bin:/usr/bin:/bin";

/// Makes `cmd` a confined child: cleared environment, `dir` as its folder, its home and its
/// temporary folder, the memory and output limits, and `sandbox`'s namespace.
pub fn confine(cmd: &mut Command, dir: &Path, limits: &Limits, sandbox: Sandbox) {
    cmd.env_clear()
        .env("PATH", KEPT_PATH)
        .env("LANG", "C.UTF-8")
        .env("HOME", dir)
        .env("TMPDIR", dir)
        .current_dir(dir);
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::process::CommandExt;
        let (memory, output) = (limits.memory_bytes, limits.output_bytes);
        // SAFETY: between fork and exec the closure calls only setrlimit, which is
        // async-signal-safe, and allocates nothing.
        unsafe {
            cmd.pre_exec(move || {
                for (resource, bytes) in [(libc::RLIMIT_AS, memory), (libc::RLIMIT_FSIZE, output)] {
                    if let Some(b) = bytes {
                        let lim = libc::rlimit {
                            rlim_cur: b as libc::rlim_t,
                            rlim_max: b as libc::rlim_t,
                        };
                        if libc::setrlimit(resource, &lim) == -1 {
                            return Err(std::io::Error::last_os_error());
                        }
                    }
                }
                Ok(())
            });
        }
        if sandbox == Sandbox::NetworkNamespace {
            apply_namespace(cmd);
        }
    }
}

#[cfg(target_os = "linux")]
fn apply_namespace(cmd: &mut Command) {
    use std::os::unix::process::CommandExt;
    // SAFETY: unshare is a system call; nothing is allocated between fork and exec.
    unsafe {
        cmd.pre_exec(|| match libc::unshare(libc::CLONE_NEWNET) {
            0 => Ok(()),
            _ => Err(std::io::Error::last_os_error()),
        });
    }
}

#[cfg(not(target_os = "linux"))]
fn apply_namespace(_cmd: &mut Command) {}

/// Whether a run that failed with `error_text` (as [`crate::Error`] displays it, or as a worker
/// sent it back) stopped at a limit that `limits` raises: its wall-time, output or memory
/// limit was lower than `limits`' (read from the message: "time limit of S s", "output limit
/// of N MB", "memory limit is N MB"). Such a failure says nothing about the model, so a rerun
/// with the higher limit simulates the point again instead of keeping the failure. (A run whose
/// ExpandObjects, capped at 120 s, timed out under a longer limit reads as raised too.)
pub fn limit_raised(error_text: &str, limits: &Limits) -> bool {
    let number_after = |marker: &str, unit: &str| -> Option<f64> {
        let (_, rest) = error_text.split_once(marker)?;
        rest.split_once(unit)?.0.trim().parse::<f64>().ok()
    };
    let mb = |bytes: Option<u64>| bytes.map_or(f64::INFINITY, |b| (b >> 20) as f64);
    if let Some(s) = number_after("exceeded its time limit of ", " s") {
        return s < limits.wall.as_secs_f64();
    }
    if let Some(m) = number_after("past its output limit of ", " MB") {
        return m < mb(limits.output_bytes);
    }
    if let Some(m) = number_after("its memory limit is ", " MB") {
        return m < mb(limits.memory_bytes);
    }
    false
}

/// Why a confined process that ended by `signal` ended, where a limit explains it.
pub fn signal_reason(signal: i32, limits: &Limits) -> String {
    #[cfg(target_os = "linux")]
    {
        if signal == libc::SIGXFSZ {
            return format!(
                "it wrote a file past its output limit of {} MB",
                limits.output_bytes.unwrap_or(0) >> 20
            );
        }
        if matches!(
            signal,
            libc::SIGSEGV | libc::SIGABRT | libc::SIGKILL | libc::SIGBUS
        ) {
            if let Some(m) = limits.memory_bytes {
                return format!(
                    "killed by signal {signal} (its memory limit is {} MB: a run that needs more fails this way)",
                    m >> 20
                );
            }
        }
    }
    let _ = limits;
    format!("killed by signal {signal}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failure_at_a_lower_limit_is_raised_by_a_higher_one_only() {
        let limits = Limits::default();
        let timeout = |s: f64| {
            crate::Error::Timeout {
                dir: "/x/point_001".into(),
                seconds: s,
            }
            .to_string()
        };
        assert!(limit_raised(&timeout(0.05), &limits));
        assert!(!limit_raised(&timeout(900.0), &limits));
        assert!(!limit_raised(&timeout(1200.0), &limits));
        let tight = Limits {
            output_bytes: Some(256 << 10),
            memory_bytes: Some(512 << 20),
            ..limits
        };
        let stopped = |signal| {
            format!(
                "EnergyPlus stopped in /x: {}",
                signal_reason(signal, &tight)
            )
        };
        #[cfg(target_os = "linux")]
        {
            assert!(limit_raised(&stopped(libc::SIGXFSZ), &limits));
            assert!(!limit_raised(&stopped(libc::SIGXFSZ), &tight));
            assert!(limit_raised(&stopped(libc::SIGKILL), &limits));
            assert!(!limit_raised(&stopped(libc::SIGKILL), &tight));
        }
        let _ = stopped;
        assert!(!limit_raised(
            "EnergyPlus failed in /x: results invalid: 1 message",
            &limits
        ));
    }
}
