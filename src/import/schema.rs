//! The JSON schemas (draft 2020-12, like fdd's own in `fdd_monitor::log::schema`) of the topics
//! `fdd import` writes, built from the mapping: each field's description says its unit and the
//! CSV column and scaling it came from, so the log documents its own provenance.

use super::mapping::TopicSpec;

/// JSON string literal of `s` (quotes and escapes).
pub fn json_string(s: &str) -> String {
    // Serializing a `str` cannot fail.
    serde_json::to_string(s).unwrap_or_else(|_| String::from("\"\""))
}

/// The schema record's name of an imported topic: `fdd.import` and the topic's segments
/// (`/turbo/p_im` -> `fdd.import.turbo.p_im`).
pub fn schema_name(topic: &str) -> String {
    format!("fdd.import{}", topic.replace('/', "."))
}

/// The JSON schema of an imported topic (not one of fdd's built-in topics).
pub fn topic_schema(t: &TopicSpec) -> String {
    let name = schema_name(&t.topic);
    let what = t.description.as_deref().unwrap_or(t.topic.as_str());
    let mut props = Vec::with_capacity(t.fields.len());
    for f in &t.fields {
        let lead = f
            .description
            .as_deref()
            .or(t.description.as_deref())
            .unwrap_or(f.name.as_str());
        let desc = format!(
            "{lead}, {}; CSV column `{}` x {} + {}; null when not finite",
            f.unit, f.column, f.scale, f.offset
        );
        props.push(format!(
            "    {}: {{\"type\": [\"number\", \"null\"], \"description\": {}}}",
            json_string(&f.name),
            json_string(&desc)
        ));
    }
    let required: Vec<String> = t.fields.iter().map(|f| json_string(&f.name)).collect();
    format!(
        "{{\n  \"$schema\": \"https://json-schema.org/draft/2020-12/schema\",\n  \"title\": {},\n  \"description\": {},\n  \"type\": \"object\",\n  \"properties\": {{\n{}\n  }},\n  \"required\": [{}],\n  \"additionalProperties\": false\n}}\n",
        json_string(&name),
        json_string(&format!(
            "{what}. Imported by fdd import from a CSV file. Log time = the row's time, ns."
        )),
        props.join(",\n"),
        required.join(", ")
    )
}

/// Schema name of the imported truth topic.
pub const TRUTH_SCHEMA_NAME: &str = "fdd.import.Truth";

/// JSON schema of the imported truth topic: fdd's truth shape (`fault`, `fault_active`,
/// `fault_observable`, as `/truth/intake`) with a `value` that is always `null`, since no true
/// value is known of measured data (fdd's replay then only skips the estimate's error).
pub const TRUTH_SCHEMA: &str = r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.import.Truth",
  "description": "Ground truth of an imported log, as given on the fdd import command line (--fault NAME --fault-onset-s T). Log time = the row's time, ns.",
  "type": "object",
  "properties": {
    "value": {"type": ["number", "null"], "description": "the true value of the monitored quantity: null, unknown for measured data"},
    "fault": {"type": "string", "description": "the fault present at this row: the --fault name from its onset on, none before (and in a fault-free log)"},
    "fault_active": {"type": "boolean", "description": "whether the fault is active at this row (row time >= --fault-onset-s)"},
    "fault_observable": {"type": "boolean", "description": "as fault_active: a sensor fault is taken to show in every row once active"}
  },
  "required": ["value", "fault", "fault_active", "fault_observable"],
  "additionalProperties": false
}
"#;

/// A truth message: `{"value":null,"fault":...,"fault_active":...,"fault_observable":...}`.
pub fn truth_message(fault: &str, active: bool) -> Vec<u8> {
    format!(
        "{{\"value\":null,\"fault\":{},\"fault_active\":{active},\"fault_observable\":{active}}}",
        json_string(fault)
    )
    .into_bytes()
}

#[cfg(test)]
mod tests {
    use super::super::mapping::Mapping;
    use super::*;

    #[test]
    fn schemas_are_json_and_name_unit_column_and_scaling() {
        let m = Mapping::parse(
            r#"
[time]
column = "t"
unit = "s"
[[topics]]
topic = "/turbo/p_im"
description = "intake manifold \"pressure\""
fields = [{ name = "pressure_pa", column = "p_im", unit = "Pa", scale = 1000 }]
"#,
            "m.toml",
        )
        .expect("valid");
        let s = topic_schema(&m.topics[0]);
        let v: serde_json::Value = serde_json::from_str(&s).expect("JSON");
        assert_eq!(v["title"], "fdd.import.turbo.p_im");
        let d = v["properties"]["pressure_pa"]["description"]
            .as_str()
            .expect("description");
        assert!(d.contains("Pa") && d.contains("`p_im` x 1000 + 0"), "{d}");
        assert_eq!(v["required"][0], "pressure_pa");
        let _: serde_json::Value = serde_json::from_str(TRUTH_SCHEMA).expect("JSON");
        let t: serde_json::Value =
            serde_json::from_slice(&truth_message("pim_gain_1.15", true)).expect("JSON");
        assert_eq!(t["fault"], "pim_gain_1.15");
        assert_eq!(t["fault_active"], true);
        assert!(t["value"].is_null());
    }
}
