//! Builders by name: the one registry type behind agent kinds
//! ([`crate::agent::AgentRegistry`]), set metrics ([`crate::metric::MetricRegistry`]) and
//! embedding methods ([`crate::embed::EmbeddingRegistry`]).
//!
//! A name picks an entry; the entry builds a `Box<T>` from the parameters of its table
//! (a TOML table) and a context `C` (what the caller knows besides the table: the
//! metrics' period, for one). A kind's parameters are a serde struct with
//! `#[serde(deny_unknown_fields, default)]` ([`Registry::register_params`]): unknown
//! keys are errors that name the key, and the resolved table (defaults included) is
//! what a run records. A new agent, metric or embedding is one file plus one
//! registration line.
//!
//! ```
//! use smspace::registry::{Registry, RegistryError};
//!
//! /// Greetings, by language.
//! trait Greeting { fn say(&self) -> String; }
//! struct Hello { name: String }
//! impl Greeting for Hello { fn say(&self) -> String { format!("hello {}", self.name) } }
//! #[derive(serde::Serialize, serde::Deserialize)]
//! #[serde(deny_unknown_fields, default)]
//! struct HelloParams { name: String }
//! impl Default for HelloParams { fn default() -> Self { Self { name: "world".into() } } }
//!
//! #[derive(Debug)]
//! struct Error(String);
//! impl RegistryError for Error {
//!     fn unknown(name: &str, known: String) -> Self { Error(format!("no {name}; known: {known}")) }
//!     fn invalid_table(name: &str, reason: String) -> Self { Error(format!("{name}: {reason}")) }
//! }
//!
//! let mut greetings: Registry<dyn Greeting, (), Error> = Registry::empty();
//! greetings.register_params("en", "English", |p: &HelloParams, _: &()| Ok(Box::new(Hello { name: p.name.clone() })));
//! let table: toml::Table = toml::from_str("name = \"agent\"").unwrap();
//! let (greeting, resolved) = greetings.make("en", &table, &()).unwrap();
//! assert_eq!(greeting.say(), "hello agent");
//! assert_eq!(resolved["name"].as_str(), Some("agent"));
//! assert!(greetings.make("fr", &table, &()).is_err());
//! assert_eq!(greetings.defaults("en").unwrap()["name"].as_str(), Some("world"));
//! ```

use std::collections::BTreeMap;
use std::sync::Arc;

use serde::de::DeserializeOwned;
use serde::Serialize;

/// The errors a registry raises on its own, as the error type of its entries.
pub trait RegistryError {
    /// No entry is registered under `name`; `known` lists the registered names.
    fn unknown(name: &str, known: String) -> Self;
    /// The parameter table does not fit the entry `name`: `reason` names the key.
    fn invalid_table(name: &str, reason: String) -> Self;
}

/// Builds one entry's value from its parameter table and the context; returns it with
/// the resolved table (defaults included).
pub type Builder<T, C, E> =
    Arc<dyn Fn(&toml::Table, &C) -> Result<(Box<T>, toml::Table), E> + Send + Sync>;

/// Reads a TOML document whose every top-level table is a parameter table of one
/// entry, as that entry's parameters: the reader's error (with the span of the key or
/// value it refuses, in the document) or `Ok`.
pub type TextReader = Arc<dyn Fn(&str) -> Result<(), toml::de::Error> + Send + Sync>;

struct Entry<T: ?Sized, C, E> {
    summary: String,
    defaults: toml::Table,
    build: Builder<T, C, E>,
    read: Option<TextReader>,
}

impl<T: ?Sized, C, E> Clone for Entry<T, C, E> {
    fn clone(&self) -> Self {
        Self {
            summary: self.summary.clone(),
            defaults: self.defaults.clone(),
            build: self.build.clone(),
            read: self.read.clone(),
        }
    }
}

/// Builders of `Box<T>` by name, from a parameter table and a context `C`, failing
/// with `E`.
pub struct Registry<T: ?Sized, C, E> {
    entries: BTreeMap<String, Entry<T, C, E>>,
}

impl<T: ?Sized, C, E> Clone for Registry<T, C, E> {
    fn clone(&self) -> Self {
        Self {
            entries: self.entries.clone(),
        }
    }
}

impl<T: ?Sized, C, E> Default for Registry<T, C, E> {
    fn default() -> Self {
        Self {
            entries: BTreeMap::new(),
        }
    }
}

impl<T: ?Sized, C, E> std::fmt::Debug for Registry<T, C, E> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.entries.keys()).finish()
    }
}

impl<T: ?Sized, C, E: RegistryError> Registry<T, C, E> {
    /// A registry without any entry.
    pub fn empty() -> Self {
        Self::default()
    }

    /// Registers (or replaces) `name` with a builder of its own; `defaults` is its
    /// parameter table with every default (empty when it has none or cannot say).
    pub fn register(
        &mut self,
        name: impl Into<String>,
        summary: impl Into<String>,
        defaults: toml::Table,
        build: Builder<T, C, E>,
    ) {
        self.entries.insert(
            name.into(),
            Entry {
                summary: summary.into(),
                defaults,
                build,
                read: None,
            },
        );
    }

    /// Registers `name` whose parameters are the serde struct `P` (with
    /// `#[serde(deny_unknown_fields, default)]`), built by `new` from them and the
    /// context.
    pub fn register_params<P, F>(&mut self, name: &str, summary: &str, new: F)
    where
        P: DeserializeOwned + Serialize + Default + 'static,
        F: Fn(&P, &C) -> Result<Box<T>, E> + Send + Sync + 'static,
        C: 'static,
        E: 'static,
        T: 'static,
    {
        let entry = name.to_owned();
        let build = move |table: &toml::Table, context: &C| {
            let params: P =
                toml::Value::Table(table.clone())
                    .try_into()
                    .map_err(|e: toml::de::Error| {
                        E::invalid_table(&entry, e.to_string().trim_end().to_owned())
                    })?;
            let built = new(&params, context)?;
            Ok((built, table_of(&params).unwrap_or_else(|| table.clone())))
        };
        let defaults = table_of(&P::default()).unwrap_or_default();
        self.register(name, summary, defaults, Arc::new(build));
        let read: TextReader =
            Arc::new(|text: &str| toml::from_str::<BTreeMap<String, P>>(text).map(drop));
        if let Some(entry) = self.entries.get_mut(name) {
            entry.read = Some(read);
        }
    }

    /// The registered names, in order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.entries.keys().map(String::as_str)
    }

    /// Whether `name` is registered.
    pub fn contains(&self, name: &str) -> bool {
        self.entries.contains_key(name)
    }

    /// One line on an entry, if registered.
    pub fn summary(&self, name: &str) -> Option<&str> {
        self.entries.get(name).map(|e| e.summary.as_str())
    }

    /// The parameter table of an entry with every default, if registered.
    pub fn defaults(&self, name: &str) -> Option<&toml::Table> {
        self.entries.get(name).map(|e| &e.defaults)
    }

    /// Reads `document`, a TOML text whose every top-level table holds parameters of
    /// the entry `name` (a file's table with its other lines blanked, so that lines
    /// keep their numbers), as those parameters: the reader's error, whose span
    /// locates the key or value it refuses, or `None` when it reads or the entry has no
    /// parameter struct ([`register_params`](Self::register_params) gives it one).
    /// Configuration readers use it to point at the line of a bad key, whatever the
    /// entry.
    pub fn read_error(&self, name: &str, document: &str) -> Option<toml::de::Error> {
        let read = self.entries.get(name)?.read.as_ref()?;
        read(document).err()
    }

    /// Builds the entry `name` from its parameter table; returns it with the resolved
    /// table (defaults included). An unknown name is an error listing the known ones.
    pub fn make(
        &self,
        name: &str,
        table: &toml::Table,
        context: &C,
    ) -> Result<(Box<T>, toml::Table), E> {
        let entry = self
            .entries
            .get(name)
            .ok_or_else(|| E::unknown(name, self.names().collect::<Vec<_>>().join(", ")))?;
        (entry.build)(table, context)
    }
}

/// The TOML table of a parameter struct, if it serialises to one (a struct of named
/// fields does; `None` fields are left out, as TOML has no null).
pub fn table_of<P: Serialize>(params: &P) -> Option<toml::Table> {
    match toml::Value::try_from(params) {
        Ok(toml::Value::Table(t)) => Some(t),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, PartialEq)]
    enum Error {
        Unknown(String, String),
        Table(String, String),
    }
    impl RegistryError for Error {
        fn unknown(name: &str, known: String) -> Self {
            Error::Unknown(name.into(), known)
        }
        fn invalid_table(name: &str, reason: String) -> Self {
            Error::Table(name.into(), reason)
        }
    }

    #[derive(Debug, Default, serde::Serialize, serde::Deserialize)]
    #[serde(deny_unknown_fields, default)]
    struct Scale {
        factor: f64,
    }

    fn registry() -> Registry<dyn Fn(f64) -> f64 + Send + Sync, f64, Error> {
        let mut r: Registry<dyn Fn(f64) -> f64 + Send + Sync, f64, Error> = Registry::empty();
        r.register_params(
            "scale",
            "times a factor, plus the context",
            |p: &Scale, c: &f64| {
                let (f, c) = (p.factor, *c);
                let scaled: Box<dyn Fn(f64) -> f64 + Send + Sync> = Box::new(move |x| f * x + c);
                Ok(scaled)
            },
        );
        r
    }

    #[test]
    fn entries_build_from_their_table_and_context() {
        let table: toml::Table = toml::from_str("factor = 3.0").unwrap();
        let (f, resolved) = registry().make("scale", &table, &1.0).unwrap();
        assert_eq!(f(2.0), 7.0);
        assert_eq!(resolved["factor"].as_float(), Some(3.0));
        let (f, resolved) = registry().make("scale", &toml::Table::new(), &0.0).unwrap();
        assert_eq!((f(2.0), resolved["factor"].as_float()), (0.0, Some(0.0)));
    }

    #[test]
    fn a_table_s_text_is_read_with_the_line_of_a_bad_key() {
        let r = registry();
        let at = |text: &str| {
            let err = r.read_error("scale", text).expect("an error");
            let start = err.span().expect("a span").start;
            text[..start].matches('\n').count() + 1
        };
        assert_eq!(at("[t]\n\nfacter = 2.0\n"), 3);
        assert_eq!(at("[t]\nfactor = \"two\"\n"), 2);
        assert!(r.read_error("scale", "[t]\nfactor = 2.0\n").is_none());
        assert!(r.read_error("other", "[t]\nfacter = 2.0\n").is_none());
    }

    #[test]
    fn unknown_names_and_keys_are_errors_that_name_them() {
        let Err(err) = registry().make("scal", &toml::Table::new(), &0.0) else {
            panic!("an unknown name was built");
        };
        assert_eq!(err, Error::Unknown("scal".into(), "scale".into()));
        let table: toml::Table = toml::from_str("facter = 3.0").unwrap();
        let Err(Error::Table(name, reason)) = registry().make("scale", &table, &0.0) else {
            panic!("an unknown key was accepted");
        };
        assert!(name == "scale" && reason.contains("facter"), "{reason}");
    }
}
