//! Reading URDF: links become frames, joints become chains of primitives, links' `<inertial>`
//! become bodies. `urdf-rs` reads the values; `roxmltree` gives every element its line, so
//! malformed XML and every problem name a line.
//!
//! A joint from link P to link C with `<origin xyz rpy>` and `<axis>` is the chain
//! `tx ty tz` (the non-zero ones), `rz(yaw) ry(pitch) rx(roll)` (URDF's fixed-axis roll,
//! pitch, yaw: `R = Rz Ry Rx`), then the motion: `rk(q)`/`tk(q)` when the axis is `+e_k`, else
//! `rz(α) ry(β)` turning `e_z` onto the axis, `rz(q)`/`tz(q)`, and `ry(−β) rz(−α)` back. The
//! last frame of the chain is link C's. Constant chains fold into one transform at plan time
//! (docs/derivations.md §8).

use std::collections::HashMap;
use std::path::Path;

use crate::error::{FrameField, ModelError, Problem, Site};
use crate::model::Model;
use crate::primitive::{Primitive, PrimitiveKind, Value};
use crate::source::{check_xml_shape, LineIndex};
use crate::spec::{FrameSpec, InputSpec, ModelSpec, VariableSpec};
use crate::validate::validate;

/// How to read a URDF file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UrdfOptions {
    /// Put six variables `root_x root_y root_z root_yaw root_pitch root_roll` (tx ty tz rz ry
    /// rx) between the world and the root link: a floating base.
    pub floating_base: bool,
}

/// The names of the floating base's variables, outermost first, with their primitives.
pub const FLOATING_BASE: [(&str, PrimitiveKind); 6] = [
    ("root_x", PrimitiveKind::Tx),
    ("root_y", PrimitiveKind::Ty),
    ("root_z", PrimitiveKind::Tz),
    ("root_yaw", PrimitiveKind::Rz),
    ("root_pitch", PrimitiveKind::Ry),
    ("root_roll", PrimitiveKind::Rx),
];

/// Reads a model from URDF text. `source_name` (a file name) prefixes every message.
///
/// ```
/// use tree_model::{from_urdf_str, UrdfOptions};
/// let urdf = r#"<robot name="arm">
///   <link name="base"/>
///   <link name="upper"><inertial><origin xyz="0 0 0.2"/><mass value="2"/>
///     <inertia ixx="0.03" ixy="0" ixz="0" iyy="0.03" iyz="0" izz="0.01"/></inertial></link>
///   <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
///     <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="5" velocity="1"/></joint>
/// </robot>"#;
/// let model = from_urdf_str(urdf, Some("arm.urdf"), UrdfOptions::default())?;
/// assert_eq!(model.variables[0].name, "shoulder");
/// assert_eq!(model.variables[0].limits, Some([-1.0, 1.0]));
/// let floating = from_urdf_str(urdf, None, UrdfOptions { floating_base: true })?;
/// assert_eq!(floating.dof(), 7);
/// # Ok::<(), tree_model::ModelError>(())
/// ```
pub fn from_urdf_str(
    text: &str,
    source_name: Option<&str>,
    options: UrdfOptions,
) -> Result<Model, ModelError> {
    let src = source_name.map(str::to_string);
    let fail =
        |message: String, line: Option<usize>| ModelError::single(src.clone(), message, line);
    // Line of a byte offset (roxmltree's own lookup rescans the text each time).
    let lines = LineIndex::new(text);
    let line_at = |offset: usize| lines.of(offset);
    // Bounded before parsing: urdf-rs recurses per level (a stack overflow at ~15 000), and
    // roxmltree checks an element's attributes for duplicates pairwise.
    check_xml_shape(text, &lines).map_err(|(message, line)| fail(message, Some(line)))?;
    let document = roxmltree::Document::parse(text)
        .map_err(|e| fail(format!("XML error: {e}"), Some(e.pos().row as usize)))?;
    let root = document.root_element();
    if root.tag_name().name() != "robot" {
        return Err(fail(
            format!(
                "URDF: the root element is <{}>, not <robot>",
                root.tag_name().name()
            ),
            Some(line_at(root.range().start)),
        ));
    }
    // The line of each <link> and <joint>, by name.
    let mut link_lines = HashMap::new();
    let mut joint_lines = HashMap::new();
    for node in root.children().filter(|n| n.is_element()) {
        let line = line_at(node.range().start);
        let name = node.attribute("name").unwrap_or_default().to_string();
        let (lines, what) = match node.tag_name().name() {
            "link" => (&mut link_lines, "link"),
            "joint" => (&mut joint_lines, "joint"),
            _ => continue,
        };
        if lines.insert(name.clone(), line).is_some() {
            return Err(fail(format!("URDF: duplicate {what} `{name}`"), Some(line)));
        }
    }
    check_numbers(root, &line_at).map_err(|(message, line)| fail(message, Some(line)))?;
    check_required(root, &line_at).map_err(|(message, line)| fail(message, Some(line)))?;
    let robot = urdf_rs::read_from_string(text).map_err(|e| fail(format!("URDF: {e}"), None))?;
    let joint_line = |name: &str| joint_lines.get(name).copied();
    let link_line = |name: &str| link_lines.get(name).copied();

    // The tree: each link's parent joint, every link reached from one root.
    let links: HashMap<&str, usize> = robot
        .links
        .iter()
        .enumerate()
        .map(|(i, l)| (l.name.as_str(), i))
        .collect();
    let mut parent_joint: Vec<Option<usize>> = vec![None; robot.links.len()];
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); robot.links.len()];
    for (j, joint) in robot.joints.iter().enumerate() {
        let line = joint_line(&joint.name);
        let name = &joint.name;
        let Some(&p) = links.get(joint.parent.link.as_str()) else {
            return Err(fail(
                format!(
                    "URDF: joint `{name}`: parent link `{}` does not exist",
                    joint.parent.link
                ),
                line,
            ));
        };
        let Some(&c) = links.get(joint.child.link.as_str()) else {
            return Err(fail(
                format!(
                    "URDF: joint `{name}`: child link `{}` does not exist",
                    joint.child.link
                ),
                line,
            ));
        };
        if let Some(other) = parent_joint[c] {
            return Err(fail(
                format!(
                    "URDF: link `{}` has two parents (joints `{}` and `{name}`); a tree has one",
                    joint.child.link, robot.joints[other].name
                ),
                line,
            ));
        }
        use urdf_rs::JointType::*;
        match joint.joint_type {
            Revolute | Continuous | Prismatic | Fixed => {}
            ref other => {
                return Err(fail(
                    format!(
                        "URDF: joint `{name}` is {}; only revolute, continuous, prismatic and fixed joints are supported inside the tree (a free root: the floating-base option)",
                        format!("{other:?}").to_lowercase()
                    ),
                    line,
                ));
            }
        }
        if let Some(m) = &joint.mimic {
            return Err(fail(
                format!(
                    "URDF: joint `{name}` mimics joint `{}`; mimic joints are not supported",
                    m.joint
                ),
                line,
            ));
        }
        parent_joint[c] = Some(j);
        children[p].push(j);
    }
    if robot.links.is_empty() {
        return Err(fail(
            "URDF: <robot> has no <link>: a robot needs at least one".into(),
            Some(line_at(root.range().start)),
        ));
    }
    let roots: Vec<usize> = (0..robot.links.len())
        .filter(|&l| parent_joint[l].is_none())
        .collect();
    let root_link = match roots[..] {
        [r] => r,
        [] => {
            return Err(fail(
                "URDF: every link has a parent joint: the joints form a cycle".into(),
                None,
            ))
        }
        _ => {
            let names: Vec<&str> = roots
                .iter()
                .map(|&r| robot.links[r].name.as_str())
                .collect();
            return Err(fail(
                format!(
                    "URDF: {} links have no parent joint ({}); a tree has one root",
                    names.len(),
                    names.join(", ")
                ),
                link_line(names[1]),
            ));
        }
    };

    let name = if robot.name.is_empty() {
        source_name
            .and_then(|s| Path::new(s).file_stem())
            .map_or("robot".into(), |s| s.to_string_lossy().into_owned())
    } else {
        robot.name.clone()
    };
    let mut spec = ModelSpec::new(name);
    // The source line of each frame, for validation problems.
    let mut frame_lines: Vec<Option<usize>> = Vec::new();
    let mut push = |spec: &mut ModelSpec,
                    name: String,
                    parent: Option<String>,
                    kind: PrimitiveKind,
                    value: Value,
                    line: Option<usize>| {
        spec.frames.push(FrameSpec {
            name,
            parent,
            primitives: vec![Primitive { kind, value }],
            mass: None,
            com: None,
            inertia: None,
        });
        frame_lines.push(line);
    };

    let root_name = robot.links[root_link].name.clone();
    // A root link called `world` is the world frame itself (ROS's convention for a robot
    // bolted to the ground); its children hang off our world.
    let root_is_world = root_name == "world";
    if root_is_world {
        let inertial = &robot.links[root_link].inertial;
        if inertial.mass.value != 0.0 || options.floating_base {
            return Err(fail(
                "URDF: the root link is `world`, the fixed ground: it can carry no mass and take no floating base".into(),
                link_line(&root_name),
            ));
        }
    } else if options.floating_base {
        let mut parent = None;
        for (k, (var, kind)) in FLOATING_BASE.iter().enumerate() {
            if joint_lines.contains_key(*var) {
                return Err(fail(
                    format!("URDF: joint `{var}` clashes with the floating base's variable of that name"),
                    joint_line(var),
                ));
            }
            let name = if k == 5 {
                root_name.clone()
            } else {
                var.to_string()
            };
            push(
                &mut spec,
                name.clone(),
                parent,
                *kind,
                Value::Variable(var.to_string()),
                link_line(&root_name),
            );
            parent = Some(name);
        }
    } else {
        push(
            &mut spec,
            root_name.clone(),
            None,
            PrimitiveKind::Tx,
            Value::Constant(0.0),
            link_line(&root_name),
        );
    }
    // Each link's frame; `None` is the world.
    let mut link_frame: Vec<Option<usize>> = vec![None; robot.links.len()];
    if !root_is_world {
        link_frame[root_link] = Some(spec.frames.len() - 1);
    }

    // Parents before children: walk the tree with an explicit stack (no recursion depth).
    let mut stack: Vec<usize> = children[root_link].iter().rev().copied().collect();
    while let Some(j) = stack.pop() {
        let joint = &robot.joints[j];
        let line = joint_line(&joint.name);
        let parent_link = links[joint.parent.link.as_str()];
        let child_link = links[joint.child.link.as_str()];
        let mut chain: Vec<(PrimitiveKind, Value)> = Vec::new();
        let constant = |kind, x: f64| (kind, Value::Constant(x));
        let xyz = joint.origin.xyz.0;
        let rpy = joint.origin.rpy.0;
        if xyz.iter().chain(rpy.iter()).any(|x| !x.is_finite()) {
            return Err(fail(
                format!("URDF: joint `{}`: origin is not finite", joint.name),
                line,
            ));
        }
        for (k, kind) in [PrimitiveKind::Tx, PrimitiveKind::Ty, PrimitiveKind::Tz]
            .into_iter()
            .enumerate()
        {
            if xyz[k] != 0.0 {
                chain.push(constant(kind, xyz[k]));
            }
        }
        for (x, kind) in [
            (rpy[2], PrimitiveKind::Rz),
            (rpy[1], PrimitiveKind::Ry),
            (rpy[0], PrimitiveKind::Rx),
        ] {
            if x != 0.0 {
                chain.push(constant(kind, x));
            }
        }
        use urdf_rs::JointType::*;
        if joint.joint_type != Fixed {
            let a = joint.axis.xyz.0;
            let norm = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
            if !(norm.is_finite() && norm > 0.0) {
                return Err(fail(
                    format!(
                        "URDF: joint `{}`: axis [{} {} {}] is zero or not finite",
                        joint.name, a[0], a[1], a[2]
                    ),
                    line,
                ));
            }
            let a = a.map(|x| x / norm);
            let prismatic = joint.joint_type == Prismatic;
            let variable = Value::Variable(joint.name.clone());
            let on_axis = (0..3).find(|&k| a[k] == 1.0);
            match on_axis {
                Some(k) => {
                    let kinds = if prismatic {
                        [PrimitiveKind::Tx, PrimitiveKind::Ty, PrimitiveKind::Tz]
                    } else {
                        [PrimitiveKind::Rx, PrimitiveKind::Ry, PrimitiveKind::Rz]
                    };
                    chain.push((kinds[k], variable));
                }
                None => {
                    // Rz(α) Ry(β) e_z = a.
                    let beta = a[2].clamp(-1.0, 1.0).acos();
                    let alpha = a[1].atan2(a[0]);
                    if alpha != 0.0 {
                        chain.push(constant(PrimitiveKind::Rz, alpha));
                    }
                    chain.push(constant(PrimitiveKind::Ry, beta));
                    let kind = if prismatic {
                        PrimitiveKind::Tz
                    } else {
                        PrimitiveKind::Rz
                    };
                    chain.push((kind, variable));
                    chain.push(constant(PrimitiveKind::Ry, -beta));
                    if alpha != 0.0 {
                        chain.push(constant(PrimitiveKind::Rz, -alpha));
                    }
                }
            }
            let mut settings = VariableSpec {
                name: joint.name.clone(),
                ..VariableSpec::default()
            };
            if let Some(d) = &joint.dynamics {
                if d.damping != 0.0 {
                    settings.damping = Some(d.damping);
                }
            }
            if joint.joint_type != Continuous {
                let l = &joint.limit;
                if l.lower != 0.0 || l.upper != 0.0 {
                    settings.limits = Some([l.lower, l.upper]);
                }
            }
            // Every joint is actuated: an input on its variable, named after it, with
            // ±effort as its limits when the URDF gives an effort.
            let effort = joint.limit.effort;
            spec.inputs.push(InputSpec {
                name: joint.name.clone(),
                variable: Some(joint.name.clone()),
                limits: (effort > 0.0).then_some([-effort, effort]),
            });
            spec.variables.push(settings);
        }
        if chain.is_empty() {
            chain.push(constant(PrimitiveKind::Tx, 0.0));
        }
        let mut parent = link_frame[parent_link].map(|f| spec.frames[f].name.clone());
        let last = chain.len() - 1;
        for (i, (kind, value)) in chain.into_iter().enumerate() {
            let name = if i == last {
                robot.links[child_link].name.clone()
            } else {
                format!("{}_{}", joint.name, i + 1)
            };
            push(&mut spec, name.clone(), parent, kind, value, line);
            parent = Some(name);
        }
        link_frame[child_link] = Some(spec.frames.len() - 1);
        stack.extend(children[child_link].iter().rev().copied());
    }
    // A link the walk never reached hangs in a cycle of its own, apart from the root.
    let reached = |l: usize| l == root_link || link_frame[l].is_some();
    if let Some(l) = (0..robot.links.len()).find(|&l| !reached(l)) {
        let name = &robot.links[l].name;
        return Err(fail(
            format!(
                "URDF: link `{name}` is not reachable from the root link `{root_name}`: its joints form a cycle"
            ),
            link_line(name),
        ));
    }

    // Bodies: <inertial> origin and tensor, turned into the link's axes.
    // Problems with a body point at its <link>, other frame problems at the joint.
    let mut body_lines: HashMap<usize, Option<usize>> = HashMap::new();
    for (l, link) in robot.links.iter().enumerate() {
        let inertial = &link.inertial;
        let i = &inertial.inertia;
        let m = inertial.mass.value;
        let tensor = [
            [i.ixx, i.ixy, i.ixz],
            [i.ixy, i.iyy, i.iyz],
            [i.ixz, i.iyz, i.izz],
        ];
        if m == 0.0 && tensor.iter().flatten().all(|&x| x == 0.0) {
            continue;
        }
        let r = rpy_matrix(inertial.origin.rpy.0);
        let mut turned = [[0.0; 3]; 3];
        for a in 0..3 {
            for b in 0..3 {
                turned[a][b] = (0..3)
                    .map(|p| {
                        (0..3)
                            .map(|q| r[a][p] * tensor[p][q] * r[b][q])
                            .sum::<f64>()
                    })
                    .sum();
            }
        }
        let Some(f) = link_frame[l] else { continue };
        body_lines.insert(f, link_line(&link.name));
        let frame = &mut spec.frames[f];
        frame.mass = Some(m);
        let com = inertial.origin.xyz.0;
        frame.com = (com != [0.0; 3]).then_some(com);
        frame.inertia = Some(vec![
            turned[0][0],
            turned[1][1],
            turned[2][2],
            turned[0][1],
            turned[0][2],
            turned[1][2],
        ]);
    }

    validate(&spec).map_err(|problems| ModelError {
        source_name: src.clone(),
        problems: problems
            .into_iter()
            .map(|p| {
                let line = match &p.site {
                    Site::Frame { index, field } => match field {
                        FrameField::Mass | FrameField::Inertia | FrameField::Com => {
                            body_lines.get(index).copied().flatten()
                        }
                        _ => frame_lines.get(*index).copied().flatten(),
                    },
                    Site::VariableSettings { name } => joint_line(name),
                    _ => None,
                };
                Problem { line, ..p }
            })
            .collect(),
    })
}

/// The numeric attributes URDF's dynamics read, and how many numbers each holds.
const NUMERIC: [(&str, usize); 15] = [
    ("xyz", 3),
    ("rpy", 3),
    ("value", 1),
    ("ixx", 1),
    ("ixy", 1),
    ("ixz", 1),
    ("iyy", 1),
    ("iyz", 1),
    ("izz", 1),
    ("lower", 1),
    ("upper", 1),
    ("effort", 1),
    ("velocity", 1),
    ("damping", 1),
    ("friction", 1),
];

/// Checks every numeric attribute of the `<link>` and `<joint>` elements before urdf-rs reads
/// them (its own errors name neither element nor line): `(message, line)` of the first bad
/// one. Visuals and collisions are skipped; their numbers do not enter the dynamics.
fn check_numbers(
    root: roxmltree::Node,
    line_at: &dyn Fn(usize) -> usize,
) -> Result<(), (String, usize)> {
    let parts = root
        .children()
        .filter(|n| matches!(n.tag_name().name(), "link" | "joint"));
    for part in parts {
        let owner = format!(
            "{} `{}`",
            part.tag_name().name(),
            part.attribute("name").unwrap_or_default()
        );
        let skipped = |n: &roxmltree::Node| {
            n.ancestors()
                .any(|a| matches!(a.tag_name().name(), "visual" | "collision"))
        };
        for node in part.descendants().filter(|n| n.is_element() && !skipped(n)) {
            for (attribute, count) in NUMERIC {
                let Some(text) = node.attribute(attribute) else {
                    continue;
                };
                let numbers: Vec<&str> = text.split_whitespace().collect();
                if numbers.len() != count || numbers.iter().any(|x| x.parse::<f64>().is_err()) {
                    let expected = if count == 1 {
                        "a number".to_string()
                    } else {
                        format!("{count} numbers")
                    };
                    return Err((
                        format!(
                            "URDF: {owner}: <{} {attribute}=\"{text}\"> must be {expected}",
                            node.tag_name().name()
                        ),
                        line_at(node.range().start),
                    ));
                }
            }
        }
    }
    Ok(())
}

/// What urdf-rs requires of an element, by tag and parent tag (`""`: any parent): its
/// attributes, and the children it must have. urdf-rs says only "missing field `mass`" when
/// one is absent; checked first, the message names the link or joint and the line.
const REQUIRED: [(&str, &str, &[&str], &[&str]); 13] = [
    ("link", "robot", &["name"], &[]),
    ("joint", "robot", &["name", "type"], &["parent", "child"]),
    ("material", "", &["name"], &[]),
    ("inertial", "link", &[], &["mass", "inertia"]),
    ("mass", "inertial", &["value"], &[]),
    (
        "inertia",
        "inertial",
        &["ixx", "ixy", "ixz", "iyy", "iyz", "izz"],
        &[],
    ),
    ("visual", "link", &[], &["geometry"]),
    ("collision", "link", &[], &["geometry"]),
    ("parent", "joint", &["link"], &[]),
    ("child", "joint", &["link"], &[]),
    ("limit", "joint", &["velocity"], &[]),
    ("mimic", "joint", &["joint"], &[]),
    ("safety_controller", "joint", &["k_velocity"], &[]),
];

/// Every element of [`REQUIRED`] has its attributes and children, or an error naming the
/// link or joint it belongs to, what is missing, and the line.
fn check_required(
    root: roxmltree::Node,
    line_at: &dyn Fn(usize) -> usize,
) -> Result<(), (String, usize)> {
    for node in root.descendants().filter(|n| n.is_element()) {
        let tag = node.tag_name().name();
        let parent = node.parent_element().map(|p| p.tag_name().name());
        let Some((_, _, attributes, children)) = REQUIRED
            .iter()
            .find(|(t, p, _, _)| *t == tag && (p.is_empty() || Some(*p) == parent))
        else {
            continue;
        };
        let owner = node
            .ancestors()
            .find(|a| matches!(a.tag_name().name(), "link" | "joint"))
            .map(|a| {
                format!(
                    "{} `{}`: ",
                    a.tag_name().name(),
                    a.attribute("name").unwrap_or_default()
                )
            })
            .unwrap_or_default();
        let line = line_at(node.range().start);
        if let Some(a) = attributes.iter().find(|a| node.attribute(**a).is_none()) {
            return Err((format!("URDF: {owner}<{tag}> has no `{a}` attribute"), line));
        }
        let has = |c: &str| node.children().any(|n| n.tag_name().name() == c);
        if let Some(c) = children.iter().find(|c| !has(c)) {
            return Err((format!("URDF: {owner}<{tag}> has no <{c}>"), line));
        }
    }
    Ok(())
}

/// URDF's `R = Rz(yaw) Ry(pitch) Rx(roll)` from `[roll, pitch, yaw]`.
fn rpy_matrix([roll, pitch, yaw]: [f64; 3]) -> [[f64; 3]; 3] {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sy, cy) = yaw.sin_cos();
    [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
}

/// Reads a URDF file.
pub fn from_urdf_file(path: impl AsRef<Path>, options: UrdfOptions) -> Result<Model, ModelError> {
    let path = path.as_ref();
    let shown = path.display().to_string();
    let text = crate::source::read_model_file(path)?;
    from_urdf_str(&text, Some(&shown), options)
}

/// Reads a model file by its extension: `.urdf` as URDF (with `options`), anything else as
/// TOML (where `options.floating_base` is an error: a TOML model says its own variables).
pub fn from_file(path: impl AsRef<Path>, options: UrdfOptions) -> Result<Model, ModelError> {
    let path = path.as_ref();
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("urdf"))
    {
        return from_urdf_file(path, options);
    }
    if options.floating_base {
        return Err(ModelError::single(
            Some(path.display().to_string()),
            "a floating base is added to URDF models only; a TOML model declares its own base variables".into(),
            None,
        ));
    }
    crate::toml_format::from_toml_file(path)
}
