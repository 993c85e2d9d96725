//! `bemcal`: the command-line front end. It parses arguments and calls the library crates; all
//! domain logic lives there (see ARCHITECTURE.md).

mod cmd;

use clap::Parser;

fn main() {
    let cli = cmd::Cli::parse();
    if let Err(e) = cmd::run(cli) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
