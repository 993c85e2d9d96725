//! Field names of IDF classes, read from the engine's `Energy+.idd`.

use std::collections::HashMap;
use std::path::Path;

use crate::{io_err, Error};

/// Field names per class (keys lower-case), in field order (the name field first).
#[derive(Debug, Clone, Default)]
pub struct Idd {
    fields: HashMap<String, Vec<String>>,
}

impl Idd {
    /// Reads an IDD file.
    pub fn read(path: &Path) -> Result<Idd, Error> {
        let text = std::fs::read_to_string(path).map_err(io_err(path))?;
        Ok(Idd::parse(&text))
    }

    /// Parses IDD text: a class line starts in column 0 and ends with ',' or ';'; its fields are
    /// the following `\field` annotations.
    pub fn parse(text: &str) -> Idd {
        let mut fields: HashMap<String, Vec<String>> = HashMap::new();
        let mut current: Option<String> = None;
        for line in text.lines() {
            let body = line.split('!').next().unwrap_or("");
            if !body.starts_with([' ', '\t', '\\']) && !body.trim().is_empty() {
                let t = body.trim();
                if let Some(class) = t.strip_suffix(',').or_else(|| t.strip_suffix(';')) {
                    if !class.contains(',') {
                        current = Some(class.to_ascii_lowercase());
                        fields.entry(class.to_ascii_lowercase()).or_default();
                        continue;
                    }
                }
            }
            if let (Some(c), Some(pos)) = (&current, line.find("\\field ")) {
                let name = line[pos + 7..].trim().to_string();
                fields.get_mut(c).expect("class entry").push(name);
            }
        }
        Idd { fields }
    }

    /// 0-based index of a field (case-insensitive name) in a class.
    pub fn field_index(&self, class: &str, field: &str) -> Option<usize> {
        self.fields
            .get(&class.to_ascii_lowercase())?
            .iter()
            .position(|f| f.eq_ignore_ascii_case(field))
    }

    /// Field names of a class.
    pub fn fields(&self, class: &str) -> Option<&[String]> {
        self.fields
            .get(&class.to_ascii_lowercase())
            .map(Vec::as_slice)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_classes_and_fields() {
        let idd = Idd::parse(
            "\\group Simulation\nVersion,\n      \\unique-object\n  A1 ; \\field Version Identifier\n\nMaterial,\n  A1 , \\field Name\n  A2 , \\field Roughness\n  N1 , \\field Thickness\n  N2 ; \\field Conductivity\n",
        );
        assert_eq!(idd.field_index("MATERIAL", "conductivity"), Some(3));
        assert_eq!(idd.field_index("Version", "Version Identifier"), Some(0));
        assert_eq!(idd.field_index("Material", "Density"), None);
    }
}
