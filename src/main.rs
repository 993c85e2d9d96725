//! `bemcal`: the command-line front end. It parses arguments and calls the library crates; all
//! domain logic lives there (see ARCHITECTURE.md).

mod cmd;

use clap::Parser;

fn main() {
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
