//! Every key expression of the service, built in one place (see the table in
//! `proto/lodcloth/v1/lodcloth.proto`).

/// `<prefix>/<instance>/state`
pub fn state(prefix: &str, instance: &str) -> String {
    format!("{prefix}/{instance}/state")
}

/// `<prefix>/<instance>/metrics`
pub fn metrics(prefix: &str, instance: &str) -> String {
    format!("{prefix}/{instance}/metrics")
}

/// `<prefix>/<instance>/info` (`*` for all instances)
pub fn info(prefix: &str, instance: &str) -> String {
    format!("{prefix}/{instance}/info")
}

/// `<prefix>/<instance>/switch`
pub fn switch(prefix: &str, instance: &str) -> String {
    format!("{prefix}/{instance}/switch")
}

/// `<prefix>/<instance>/control`
pub fn control(prefix: &str, instance: &str) -> String {
    format!("{prefix}/{instance}/control")
}

/// `<prefix>/<instance>/input`
pub fn input(prefix: &str, instance: &str) -> String {
    format!("{prefix}/{instance}/input")
}

/// `<prefix>/<instance>/inputs`: every input that took effect.
pub fn inputs(prefix: &str, instance: &str) -> String {
    format!("{prefix}/{instance}/inputs")
}

/// `<prefix>/<instance>/episode_inputs`: query the inputs of the latest
/// episode so far.
pub fn episode_inputs(prefix: &str, instance: &str) -> String {
    format!("{prefix}/{instance}/episode_inputs")
}

/// `<prefix>/instances`
pub fn instances(prefix: &str) -> String {
    format!("{prefix}/instances")
}

/// `<prefix>/alive/<instance>` (`*` for all): liveliness tokens.
pub fn alive(prefix: &str, instance: &str) -> String {
    format!("{prefix}/alive/{instance}")
}

/// The instance named by a concrete key `<prefix>/<instance>/<leaf>`; None
/// for other shapes (wildcards included).
pub fn instance_of<'a>(prefix: &str, leaf: &str, key: &'a str) -> Option<&'a str> {
    let rest = key.strip_prefix(prefix)?.strip_prefix('/')?;
    let name = rest.strip_suffix(leaf)?.strip_suffix('/')?;
    (!name.is_empty() && !name.contains('/') && !name.contains('*') && !name.contains('$')).then_some(name)
}

/// The instance named by a liveliness key `<prefix>/alive/<instance>`.
pub fn alive_instance<'a>(prefix: &str, key: &'a str) -> Option<&'a str> {
    key.strip_prefix(prefix)?.strip_prefix("/alive/")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn instance_names_come_back_out_of_their_keys() {
        assert_eq!(instance_of("lodcloth", "switch", "lodcloth/a-1/switch"), Some("a-1"));
        assert_eq!(instance_of("a/b", "info", "a/b/x/info"), Some("x"));
        assert_eq!(instance_of("lodcloth", "switch", "lodcloth/*/switch"), None);
        assert_eq!(instance_of("lodcloth", "switch", "lodcloth/x/y/switch"), None);
        assert_eq!(instance_of("lodcloth", "switch", "other/x/switch"), None);
        assert_eq!(alive_instance("lodcloth", &alive("lodcloth", "h")), Some("h"));
    }
}
