//! The dashboard in `config/foxglove-layout.json` against the channels: every panel it places
//! is configured, and every message path it plots names a topic and a field that exist.

use serde_json::Value;

use crate::channels::{BASE_FRAME, TOPICS};
use crate::schema;

const LAYOUT: &str = include_str!("../../../config/foxglove-layout.json");

fn layout() -> Value {
    serde_json::from_str(LAYOUT).expect("the layout is JSON")
}

/// The panel ids the layout tree places.
fn placed(node: &Value, ids: &mut Vec<String>) {
    match node {
        Value::String(id) => ids.push(id.clone()),
        Value::Object(split) => {
            placed(&split["first"], ids);
            placed(&split["second"], ids);
        }
        other => panic!("not a layout node: {other}"),
    }
}

/// Every string in `value` that is a message path (starts with `/`), wherever it is.
fn message_paths(value: &Value, paths: &mut Vec<String>) {
    match value {
        Value::String(text) if text.starts_with('/') => paths.push(text.clone()),
        Value::Object(fields) => {
            for (key, field) in fields {
                if key.starts_with('/') {
                    paths.push(key.clone());
                }
                message_paths(field, paths);
            }
        }
        Value::Array(items) => items.iter().for_each(|item| message_paths(item, paths)),
        _ => {}
    }
}

/// Resolves `/topic.field[0].field` against the JSON channels' schemas; `Err` says what is
/// missing. A protobuf topic resolves by name alone.
fn resolve(path: &str) -> Result<(), String> {
    let (topic, fields) = path.split_once('.').unwrap_or((path, ""));
    if !TOPICS.contains(&topic) {
        return Err(format!("{path}: no topic {topic}"));
    }
    let mut node = match topic {
        "/scout/state" => schema::state(),
        "/scout/status" => schema::status(),
        "/scout/command" => schema::command(),
        _ if fields.is_empty() => return Ok(()),
        _ => {
            return Err(format!(
                "{path}: fields of a protobuf topic are not checked here"
            ));
        }
    };
    for segment in fields.split('.').filter(|s| !s.is_empty()) {
        let (name, index) = segment.split_once('[').unwrap_or((segment, ""));
        node = node["properties"]
            .get(name)
            .cloned()
            .ok_or_else(|| format!("{path}: no field {name}"))?;
        if !index.is_empty() {
            node = node
                .get("items")
                .cloned()
                .ok_or_else(|| format!("{path}: {name} is not a list"))?;
        }
    }
    Ok(())
}

#[test]
fn every_panel_placed_is_configured_and_every_configured_panel_is_placed() {
    let layout = layout();
    let mut ids = Vec::new();
    placed(&layout["layout"], &mut ids);
    let configured: Vec<&String> = layout["configById"]
        .as_object()
        .expect("configById")
        .keys()
        .collect();
    for id in &ids {
        assert!(
            configured.contains(&id),
            "{id} is placed but not configured"
        );
    }
    assert_eq!(
        ids.len(),
        configured.len(),
        "every configured panel is placed"
    );
}

#[test]
fn every_message_path_in_the_layout_names_a_topic_and_a_field_that_exist() {
    let mut paths = Vec::new();
    message_paths(&layout()["configById"], &mut paths);
    assert!(paths.len() >= 20, "{paths:?}");
    // The 3D panel's own settings name topics of other programs (goal poses it could publish).
    paths.retain(|path| {
        !["/move_base_simple/goal", "/clicked_point", "/initialpose"].contains(&path.as_str())
    });
    let wrong: Vec<String> = paths
        .iter()
        .filter_map(|path| resolve(path).err())
        .collect();
    assert_eq!(wrong, Vec::<String>::new());
    assert!(
        resolve("/scout/state.motors[0].nothing").is_err(),
        "the walk can fail"
    );
    assert!(resolve("/nothing").is_err());
    assert_eq!(layout()["configById"]["3D!odom"]["followTf"], BASE_FRAME);
}
