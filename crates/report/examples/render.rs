//! Writes `DIR/report.html` without the CLI: `cargo run -p bemcal-report --example render -- DIR [PDIR]`.

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(dir) = args.first() else {
        eprintln!("usage: render DIR [PDIR]");
        std::process::exit(2);
    };
    match bemcal_report::write_report(
        std::path::Path::new(dir),
        args.get(1).map(std::path::Path::new),
    ) {
        Ok(p) => println!("{}", p.display()),
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    }
}
