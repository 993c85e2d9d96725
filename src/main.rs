//! `bemcal`: the command-line front end. It parses arguments and calls the library crates; all
//! domain logic lives there (see ARCHITECTURE.md).

mod cmd;

/// Variable that makes bemcal panic on purpose at start, so that a test can see what a user
/// sees when bemcal has a bug.
const PANIC_TEST_VAR: &str = "BEMCAL_PANIC_TEST";

use clap::Parser;

fn main() {
    install_panic_hook();
    let cli = cmd::Cli::parse();
    // A command that prints a result behaves like other Unix tools when the reader of its output
    // goes away (`bemcal params ... | head`): it exits quietly instead of panicking on a broken
    // pipe. A server (coordinator, worker, or a calibration hosting them) keeps SIGPIPE ignored,
    // Rust's default: a client that hangs up is an error on that connection, not its death.
    #[cfg(unix)]
    if !cli.command.serves() {
        // SAFETY: restoring the default disposition of SIGPIPE before any thread starts.
        unsafe {
            libc::signal(libc::SIGPIPE, libc::SIG_DFL);
        }
    }
    if let Err(e) = cmd::run(cli) {
        if let Some(n) = e.downcast_ref::<cmd::calibrate::NotConverged>() {
            eprintln!("\n{n}");
            std::process::exit(bemcal_calibrate::NOT_CONVERGED_EXIT);
        }
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

/// Where a panic's details go: `$XDG_STATE_HOME/bemcal` (else `~/.local/state/bemcal`, else the
/// temporary folder), one file per panic.
fn crash_log() -> std::path::PathBuf {
    let state = std::env::var_os("XDG_STATE_HOME")
        .map(std::path::PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| std::path::Path::new(&h).join(".local/state")))
        .unwrap_or_else(std::env::temp_dir);
    let stamp = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis());
    state
        .join("bemcal")
        .join(format!("panic-{stamp}-{}.log", std::process::id()))
}

/// A bug in bemcal (a panic) prints a short message on stderr: what happened, where the
/// details went (the message, the command, the version, a backtrace) and how to report it;
/// the exit status stays 101.
fn install_panic_hook() {
    std::panic::set_hook(Box::new(|info| {
        let message = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "(no message)".into());
        let location = info
            .location()
            .map(|l| format!("{}:{}", l.file(), l.line()))
            .unwrap_or_default();
        let path = crash_log();
        let details = format!(
            "bemcal {} panicked: {message}\nat {location}\nthread: {}\ncommand: {:?}\n\nbacktrace:\n{}\n",
            env!("CARGO_PKG_VERSION"),
            std::thread::current().name().unwrap_or("?"),
            std::env::args().collect::<Vec<_>>(),
            std::backtrace::Backtrace::force_capture()
        );
        let written = path
            .parent()
            .map(std::fs::create_dir_all)
            .transpose()
            .and_then(|_| std::fs::write(&path, details))
            .is_ok();
        eprintln!(
            "bemcal: internal error, a bug in bemcal and not in your input: {}",
            bemcal_excerpt::excerpt(&message, 300)
        );
        match written {
            true => eprintln!(
                "  the details (command, version, backtrace) are in {}\n  please report it to the bemcal developers with that file",
                path.display()
            ),
            false => eprintln!("  at {location}; please report it to the bemcal developers"),
        }
    }));
    if std::env::var_os(PANIC_TEST_VAR).is_some() {
        panic!("{PANIC_TEST_VAR} is set: a panic on purpose");
    }
}
