//! `<default>` classes: nested, each inheriting its parent's values, per kind of element.

use std::collections::HashMap;

use super::element::El;
use super::invalid;
use crate::Result;

pub(super) type Attrs = HashMap<String, String>;
/// A default class: per element kind (joint, geom, actuator, ...), its attribute values.
pub(super) type Class = HashMap<String, Attrs>;

/// The kind of default an element reads: every actuator shortcut shares one.
pub(super) fn kind_of(tag: &str) -> &str {
    match tag {
        "motor" | "position" | "velocity" | "general" | "intvelocity" | "damper" | "cylinder" | "muscle" | "adhesion" => "actuator",
        "freejoint" => "joint",
        other => other,
    }
}

fn collect_defaults(el: &El, parent: &Class, name: &str, classes: &mut HashMap<String, Class>) -> Result<()> {
    let mut class = parent.clone();
    for child in el.children.iter().filter(|c| c.tag != "default") {
        let attrs = class.entry(kind_of(&child.tag).to_owned()).or_default();
        for (k, v) in &child.attrs {
            attrs.insert(k.to_string(), v.clone());
        }
    }
    for child in el.elements("default") {
        let child_name = child.attr("class").ok_or_else(|| invalid(format!("a nested <default> has no class ({})", child.at)))?;
        collect_defaults(child, &class, child_name, classes)?;
    }
    // Checked once the nested classes are in: one of them may take its parent's name.
    if classes.insert(name.to_owned(), class).is_some() {
        return Err(invalid(format!("default class {name:?} is defined twice ({})", el.at)));
    }
    Ok(())
}

/// Every class of the file by name, the top `<default>` being class `main` (several top `<default>`s merge).
pub(super) fn classes(root: &El) -> Result<HashMap<String, Class>> {
    let mut classes = HashMap::new();
    let mut main = Class::new();
    for d in root.elements("default") {
        // The top <default> is class "main"; its children inherit from it.
        if d.attr("class").is_some_and(|name| name != "main") {
            return Err(invalid(format!("the top <default> is class \"main\" and cannot be renamed ({})", d.at)));
        }
        let mut top = HashMap::new();
        collect_defaults(d, &main, "main", &mut top)?;
        main = top.remove("main").expect("collected");
        for (name, class) in top {
            if classes.insert(name.clone(), class).is_some() {
                return Err(invalid(format!("default class {name:?} is defined twice")));
            }
        }
    }
    classes.insert("main".to_owned(), main);
    Ok(classes)
}
