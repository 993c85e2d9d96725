//! A minimal EnergyPlus IDF object model: parse, edit fields, write back.
//!
//! IDF is a list of objects `Class, field, field, ... ;` with `!` comments. bemcal only needs
//! to find objects by class and name, read or replace a field, and write the text out again; the
//! field names of a class come from the engine's `Energy+.idd` (see [`crate::idd`]).

use std::fmt::Write as _;
use std::path::Path;

use crate::idd::Idd;
use crate::Error;

/// One IDF object: its class and its fields (the first field is usually the name).
#[derive(Debug, Clone, PartialEq)]
pub struct IdfObject {
    /// The object's class (`Lights`, `Schedule:Compact`).
    pub class: String,
    /// Its fields, in order, without comments.
    pub fields: Vec<String>,
    /// 1-based line of the class keyword in the source (0 for generated objects).
    pub line: usize,
}

impl IdfObject {
    /// The object's name (its first field), if any.
    pub fn name(&self) -> Option<&str> {
        self.fields.first().map(String::as_str)
    }
}

/// An IDF file as an ordered list of objects.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Idf {
    /// The objects, in file order.
    pub objects: Vec<IdfObject>,
}

impl Idf {
    /// An empty model.
    pub fn new() -> Idf {
        Idf::default()
    }

    /// Appends an object.
    pub fn add<S: ToString>(&mut self, class: &str, fields: &[S]) {
        self.objects.push(IdfObject {
            class: class.to_string(),
            fields: fields.iter().map(|f| f.to_string()).collect(),
            line: 0,
        });
    }

    /// Parses IDF text; `path` is used in error messages only.
    pub fn parse(text: &str, path: &Path) -> Result<Idf, Error> {
        let mut objects = Vec::new();
        let mut current: Vec<String> = Vec::new();
        let mut field = String::new();
        let mut start_line = 0;
        for (i, raw) in text.lines().enumerate() {
            let line = raw.split('!').next().unwrap_or("");
            for ch in line.chars() {
                match ch {
                    ',' | ';' => {
                        if current.is_empty() && field.trim().is_empty() {
                            return Err(Error::Input {
                                path: path.to_path_buf(),
                                line: i + 1,
                                message: "a field separator with no object class before it".into(),
                            });
                        }
                        if current.is_empty() {
                            start_line = i + 1;
                        }
                        current.push(field.trim().to_string());
                        field.clear();
                        if ch == ';' {
                            let class = current.remove(0);
                            objects.push(IdfObject {
                                class,
                                fields: std::mem::take(&mut current),
                                line: start_line,
                            });
                        }
                    }
                    _ => field.push(ch),
                }
            }
            field.push(' ');
        }
        if !current.is_empty() || !field.trim().is_empty() {
            return Err(Error::Input {
                path: path.to_path_buf(),
                line: text.lines().count(),
                message: "the last object is not terminated by ';'".into(),
            });
        }
        Ok(Idf { objects })
    }

    /// Objects of a class (case-insensitive), in file order.
    pub fn of_class<'a>(&'a self, class: &'a str) -> impl Iterator<Item = &'a IdfObject> + 'a {
        self.objects
            .iter()
            .filter(move |o| o.class.eq_ignore_ascii_case(class))
    }

    /// True if any object's class starts with `prefix` (case-insensitive).
    pub fn has_class_prefix(&self, prefix: &str) -> bool {
        let p = prefix.to_ascii_lowercase();
        self.objects
            .iter()
            .any(|o| o.class.to_ascii_lowercase().starts_with(&p))
    }

    /// Writes the model as IDF text.
    pub fn to_text(&self) -> String {
        self.write(None)
    }

    /// The IDF as text with each field named from the IDD in a `!-` comment, as IDF Editor
    /// writes them (`    10.0,                     !- Watts per Floor Area`): the calibrated
    /// model a user reads field by field. Fields past the IDD's list have no comment.
    pub fn to_text_with_field_names(&self, idd: &Idd) -> String {
        self.write(Some(idd))
    }

    fn write(&self, idd: Option<&Idd>) -> String {
        let mut s = String::with_capacity(self.objects.len() * 120);
        for o in &self.objects {
            s.push_str(&o.class);
            if o.fields.is_empty() {
                s.push_str(";\n\n");
                continue;
            }
            s.push_str(",\n");
            let names = idd.and_then(|d| d.fields(&o.class)).unwrap_or_default();
            for (i, f) in o.fields.iter().enumerate() {
                let sep = if i + 1 == o.fields.len() { ';' } else { ',' };
                let cell = format!("    {f}{sep}");
                let _ = match names.get(i) {
                    // The comments in one column where the values allow it.
                    Some(name) => writeln!(s, "{cell:<29} !- {name}"),
                    None => writeln!(s, "{cell}"),
                };
            }
            s.push('\n');
        }
        s
    }
}

/// Formats a number for an IDF field: enough digits, no exponent surprises.
pub fn num(x: f64) -> String {
    if x == x.trunc() && x.abs() < 1e15 {
        format!("{x:.1}")
    } else {
        let s = format!("{x:.6}");
        let s = s.trim_end_matches('0');
        s.trim_end_matches('.').to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_edit_write_roundtrip() {
        let text = "Version,25.2;\n! comment\nMaterial, Insul ,  Rough, 0.1, 0.04, 30, 1200 ; ! tail\nZone,\n  Z1; \n";
        let idf = Idf::parse(text, Path::new("m.idf")).unwrap();
        assert_eq!(idf.objects.len(), 3);
        let m = idf.of_class("material").next().unwrap();
        assert_eq!(m.name(), Some("Insul"));
        assert_eq!(m.fields[3], "0.04");
        assert_eq!(m.line, 3);
        let again = Idf::parse(&idf.to_text(), Path::new("m.idf")).unwrap();
        assert_eq!(
            again.objects.iter().map(|o| &o.fields).collect::<Vec<_>>(),
            idf.objects.iter().map(|o| &o.fields).collect::<Vec<_>>()
        );
        let e = Idf::parse("Zone, Z1", Path::new("bad.idf")).unwrap_err();
        assert!(e.to_string().contains("bad.idf:1"), "{e}");
    }

    #[test]
    fn field_names_from_the_idd_are_comments_that_parse_back() {
        let idd = Idd::parse("Lights,\n  A1 , \\field Name\n  N1 ; \\field Watts per Floor Area\n");
        let idf = Idf::parse("Lights, L1, 10.0, 3;\nZone, Z1;\n", Path::new("m.idf")).unwrap();
        let text = idf.to_text_with_field_names(&idd);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[1], format!("{:<29} !- Name", "    L1,"), "{text}");
        assert_eq!(
            lines[2],
            format!("{:<29} !- Watts per Floor Area", "    10.0,"),
            "{text}"
        );
        // Past the IDD's fields, and in a class it does not list: no comment.
        assert_eq!(lines[3], "    3;", "{text}");
        assert!(text.contains("Zone,\n    Z1;\n"), "{text}");
        let fields = |i: &Idf| -> Vec<(String, Vec<String>)> {
            i.objects
                .iter()
                .map(|o| (o.class.clone(), o.fields.clone()))
                .collect()
        };
        let again = Idf::parse(&text, Path::new("m.idf")).unwrap();
        assert_eq!(fields(&again), fields(&idf));
    }

    #[test]
    fn numbers_format() {
        assert_eq!(num(3.0), "3.0");
        assert_eq!(num(0.015), "0.015");
        assert_eq!(num(0.1234567), "0.123457");
    }
}
