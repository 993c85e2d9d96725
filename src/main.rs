//! `bemcal`: the command-line front end. It parses arguments and calls the library crates; all
//! domain logic lives there (see ARCHITECTURE.md).

mod cmd;

use clap::Parser;

fn main() {
    // Behave like other Unix tools when the reader of our output goes away (`bemcal ... | head`):
    // exit quietly instead of panicking on a broken pipe.
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = cmd::Cli::parse();
    if let Err(e) = cmd::run(cli) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
