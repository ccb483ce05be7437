//! The TOML side of configuration, for any serde type: parse errors as one line that
//! names the place, and laying the keys a command line gave over a file's.
//!
//! Generic on purpose: `config` defines the keys, this module only knows that a key
//! is `section.key` and that its value is TOML.

use clap::parser::ValueSource;
use clap::ArgMatches;
use serde::de::DeserializeOwned;

/// Parses TOML text into `T`.
///
/// Errors are one line that names the place: `line 2 ([sources] discovery = "yes"):
/// invalid type: string "yes", expected a boolean`. toml's own message says what is
/// wrong but not which key (a wrong type points at the value), and its `Display`
/// spans several lines, so the line's section and text are quoted here.
pub(crate) fn parse<T: DeserializeOwned>(text: &str) -> anyhow::Result<T> {
    toml::from_str(text).map_err(|e| {
        let msg = e.message().replace(['\n', '\r'], " ");
        // `get`, not indexing: a span is a byte range and must never panic here.
        match e.span().and_then(|span| text.get(..span.start)) {
            Some(before) => {
                let line = before.matches('\n').count() + 1;
                // The lines before this one (the span may start mid-line).
                let above = &before[..before.rfind('\n').unwrap_or(0)];
                let section = above
                    .lines()
                    .rev()
                    .map(str::trim)
                    .find(|l| l.starts_with('['));
                let quoted: String = text
                    .lines()
                    .nth(line - 1)
                    .unwrap_or_default()
                    .trim()
                    .chars()
                    .take(80)
                    .collect();
                let place = match section {
                    Some(s) if !quoted.starts_with('[') => format!("{s} {quoted}"),
                    _ => quoted,
                };
                anyhow::anyhow!("line {line} ({place}): {msg}")
            }
            None => anyhow::anyhow!(msg),
        }
    })
}

/// Lays over `base` every `section.key` whose argument (id = the key) the command
/// line or its environment set in `matches`, taking the value from `flags` (the
/// same struct as parsed from `matches`, as TOML). A list replaces the list; a table
/// (a repeatable `KEY=VALUE` flag) adds its entries to the table.
pub(crate) fn overlay(
    mut base: toml::Table,
    flags: &toml::Table,
    matches: &ArgMatches,
) -> toml::Table {
    for id in matches.ids().map(clap::Id::as_str) {
        let given = matches!(
            matches.value_source(id),
            Some(ValueSource::CommandLine | ValueSource::EnvVariable)
        );
        let Some((section, key)) = id.split_once('.').filter(|_| given) else {
            continue;
        };
        let Some(value) = flags.get(section).and_then(|s| s.get(key)) else {
            continue;
        };
        let toml::Value::Table(table) = base
            .entry(section)
            .or_insert_with(|| toml::Table::new().into())
        else {
            continue;
        };
        match (table.get_mut(key), value) {
            (Some(toml::Value::Table(old)), toml::Value::Table(new)) => {
                old.extend(new.clone());
            }
            _ => {
                table.insert(key.to_owned(), value.clone());
            }
        }
    }
    base
}
