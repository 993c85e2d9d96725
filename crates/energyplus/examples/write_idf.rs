//! Writes the IDF of a building spec at its prior modes: `write_idf [SPEC.toml] > model.idf`.
use bemcal_energyplus::{BuildingSpec, Model};

fn main() {
    let spec = match std::env::args().nth(1) {
        Some(p) => {
            let text = std::fs::read_to_string(&p).expect("read spec");
            BuildingSpec::from_toml(&text, p.as_ref()).expect("valid spec")
        }
        None => BuildingSpec::default(),
    };
    let model = Model::generated(spec.clone());
    let v = model.values(&Default::default()).expect("values");
    print!("{}", spec.to_idf(&v).expect("idf").to_text());
}
