//! `bemcal completions SHELL`: shell completion script on stdout (clap_complete).

use clap::CommandFactory;

/// Print a completion script for a shell (bash: `bemcal completions bash >
/// ~/.local/share/bash-completion/completions/bemcal`; zsh: into a folder on `$fpath` as
/// `_bemcal`; fish: `~/.config/fish/completions/bemcal.fish`).
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The shell.
    pub shell: clap_complete::Shell,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let mut cmd = super::Cli::command();
    clap_complete::generate(a.shell, &mut cmd, "bemcal", &mut std::io::stdout());
    Ok(())
}
