//! `bemcal example`: writes a bundled example building into a folder.

use std::path::PathBuf;

use anyhow::{anyhow, Context};
use bemcal_calibrate::examples::{self, EXAMPLES};

/// Write a bundled example (model and project files) into a folder.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Example name (`office`); without it, list the examples.
    pub name: Option<String>,
    /// Folder to write the example's files into (created; existing files are never overwritten).
    #[arg(long, default_value = ".")]
    pub out: PathBuf,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let Some(name) = a.name else {
        for e in EXAMPLES {
            println!("{:<8} {}", e.name, e.about);
        }
        return Ok(());
    };
    let example = examples::find(&name).ok_or_else(|| {
        let names: Vec<&str> = EXAMPLES.iter().map(|e| e.name).collect();
        anyhow!(
            "no example '{}'; the examples are: {}",
            bemcal_excerpt::shorten(&name),
            names.join(", ")
        )
    })?;
    let written = example
        .write_to(&a.out)
        .with_context(|| format!("writing example '{name}' into {}", a.out.display()))?;
    for p in written {
        println!("{}", p.display());
    }
    Ok(())
}
