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

use crate::contact::ContactSpec;
use crate::error::{FrameField, ModelError, Problem, Site};
use crate::model::Model;
use crate::primitive::{MimicSpec, Primitive, PrimitiveKind, Value};
use crate::source::{check_xml_shape, LineIndex};
use crate::spec::{FrameSpec, InputSpec, ModelSpec, VariableSpec};
use crate::validate::validate;

/// How to read a URDF file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UrdfOptions {
    /// Put six variables `root_x root_y root_z root_yaw root_pitch root_roll` (tx ty tz rz ry
    /// rx) between the world and the root link: a floating base.
    pub floating_base: bool,
    /// Load each mimic joint as a joint of its own, its `<mimic>` ignored (Pinocchio's
    /// default, `mimic=False`): for a file whose mimic joints follow joints it does not have.
    /// By default a mimic joint follows its leader (`multiplier·q + offset`).
    pub independent_mimics: bool,
    /// Make each `<collision><sphere>` a contact sphere on its link (docs/model-format.md,
    /// "Contact"): they touch the ground a model or `--ground` gives, not each other.
    pub collision_spheres: bool,
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
/// let floating = from_urdf_str(urdf, None, UrdfOptions { floating_base: true, ..Default::default() })?;
/// assert_eq!(floating.dof(), 7);
/// # Ok::<(), tree_model::ModelError>(())
/// ```
pub fn from_urdf_str(
    text: &str,
    source_name: Option<&str>,
    options: UrdfOptions,
) -> Result<Model, ModelError> {
    let (reader, robot) = Reader::read(text, source_name)?;
    let tree = Tree::of(&robot, &reader)?;
    let name = if robot.name.is_empty() {
        source_name
            .and_then(|s| Path::new(s).file_stem())
            .map_or("robot".into(), |s| s.to_string_lossy().into_owned())
    } else {
        robot.name.clone()
    };
    let moving = |j: &urdf_rs::Joint| j.joint_type != urdf_rs::JointType::Fixed;
    if !options.floating_base && !robot.joints.iter().any(moving) {
        return Err(reader.fail(
            format!(
                "URDF: robot `{}` has no moving joint: fixed to the world it has nothing to simulate; give it a floating base (--floating-base) to simulate it as a free body",
                robot.name
            ),
            Some(reader.robot_line),
        ));
    }
    let mut out = Frames::new(ModelSpec::new(name), robot.links.len());
    root_frames(&mut out, &robot, &tree, options, &reader)?;
    // Parents before children: walk the tree with an explicit stack (no recursion depth).
    let mut stack: Vec<usize> = tree.children[tree.root].iter().rev().copied().collect();
    while let Some(j) = stack.pop() {
        joint_frames(&mut out, &robot, &robot.joints[j], &tree, options, &reader)?;
        let child = tree.links[robot.joints[j].child.link.as_str()];
        stack.extend(tree.children[child].iter().rev().copied());
    }
    // A link the walk never reached hangs in a cycle of its own, apart from the root.
    let reached = |l: usize| l == tree.root || out.link_frame[l].is_some();
    if let Some(l) = (0..robot.links.len()).find(|&l| !reached(l)) {
        let (name, root) = (&robot.links[l].name, &robot.links[tree.root].name);
        return Err(reader.fail(
            format!(
                "URDF: link `{name}` is not reachable from the root link `{root}`: its joints form a cycle"
            ),
            reader.link_line(name),
        ));
    }
    bodies(&mut out, &robot, &reader);
    if options.collision_spheres {
        collision_spheres(&mut out, &robot, &reader)?;
    }
    out.validate(&reader)
}

/// The text's lines, and the line of each `<link>` and `<joint>` by name: every problem
/// names where it is.
struct Reader {
    source_name: Option<String>,
    /// The line of `<robot>`.
    robot_line: usize,
    link_lines: HashMap<String, usize>,
    joint_lines: HashMap<String, usize>,
    /// The joints whose `<limit>` says an `effort` (urdf-rs reads an absent one as 0).
    efforts: std::collections::HashSet<String>,
    /// Each link's `<collision>` spheres, in file order (read here: the text urdf-rs reads
    /// has its collisions taken out).
    spheres: HashMap<String, Vec<CollisionSphere>>,
}

/// A `<collision>` whose geometry is a `<sphere>`.
struct CollisionSphere {
    /// The collision's `name`, if it has one.
    name: Option<String>,
    /// Its `<origin xyz>` in the link's frame.
    xyz: [f64; 3],
    radius: f64,
    line: usize,
}

impl Reader {
    /// Checks the XML's shape, numbers and required attributes with their lines, then reads
    /// the robot with urdf-rs.
    fn read(text: &str, source_name: Option<&str>) -> Result<(Self, urdf_rs::Robot), ModelError> {
        let src = source_name.map(str::to_string);
        let fail =
            |message: String, line: Option<usize>| ModelError::single(src.clone(), message, line);
        // Line of a byte offset (roxmltree's own lookup rescans the text each time).
        let lines = LineIndex::new(text);
        let line_at = |offset: usize| lines.of(offset);
        // Bounded before parsing: urdf-rs recurses per level (a stack overflow at ~15 000),
        // and roxmltree checks an element's attributes for duplicates pairwise.
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
        let modelled = modelled_text(text, root);
        let robot =
            urdf_rs::read_from_string(&modelled).map_err(|e| fail(format!("URDF: {e}"), None))?;
        let efforts = root
            .children()
            .filter(|j| j.has_tag_name("joint"))
            .filter(|j| {
                j.children()
                    .any(|l| l.has_tag_name("limit") && l.has_attribute("effort"))
            })
            .map(|j| j.attribute("name").unwrap_or_default().to_string())
            .collect();
        let spheres =
            collision_spheres_of(root, &line_at).map_err(|(m, line)| fail(m, Some(line)))?;
        let reader = Reader {
            source_name: src,
            robot_line: line_at(root.range().start),
            link_lines,
            joint_lines,
            efforts,
            spheres,
        };
        Ok((reader, robot))
    }

    /// The error `message` at `line`.
    fn fail(&self, message: String, line: Option<usize>) -> ModelError {
        ModelError::single(self.source_name.clone(), message, line)
    }

    fn joint_line(&self, name: &str) -> Option<usize> {
        self.joint_lines.get(name).copied()
    }

    fn link_line(&self, name: &str) -> Option<usize> {
        self.link_lines.get(name).copied()
    }
}

/// `n`'s child elements named `tag`.
fn elements<'a, 'input>(
    n: roxmltree::Node<'a, 'input>,
    tag: &'static str,
) -> impl Iterator<Item = roxmltree::Node<'a, 'input>> {
    n.children()
        .filter(move |c| c.is_element() && c.tag_name().name() == tag)
}

/// Every link's `<collision>` spheres, or the sentence for one that is not a finite radius
/// ≥ 0 at a finite origin, with its line.
fn collision_spheres_of(
    root: roxmltree::Node,
    line_at: &dyn Fn(usize) -> usize,
) -> Result<HashMap<String, Vec<CollisionSphere>>, (String, usize)> {
    let mut out: HashMap<String, Vec<CollisionSphere>> = HashMap::new();
    for link in elements(root, "link") {
        let link_name = link.attribute("name").unwrap_or_default();
        for collision in elements(link, "collision") {
            let geometry = elements(collision, "geometry").next();
            let Some(sphere) = geometry.and_then(|g| elements(g, "sphere").next()) else {
                continue;
            };
            let line = line_at(sphere.range().start);
            let bad = |what: String| {
                (
                    format!("URDF: link `{link_name}`: a collision sphere's {what}"),
                    line,
                )
            };
            let text = sphere.attribute("radius").unwrap_or("");
            let radius = match text.trim().parse::<f64>() {
                Ok(r) if r.is_finite() && r >= 0.0 => r,
                _ => return Err(bad(format!("radius `{text}` is not a finite number ≥ 0"))),
            };
            let mut xyz = [0.0; 3];
            let origin = elements(collision, "origin").next();
            if let Some(text) = origin.and_then(|o| o.attribute("xyz")) {
                let numbers: Vec<_> = text.split_whitespace().map(str::parse::<f64>).collect();
                match numbers[..] {
                    [Ok(x), Ok(y), Ok(z)] if [x, y, z].iter().all(|v| v.is_finite()) => {
                        xyz = [x, y, z]
                    }
                    _ => {
                        return Err(bad(format!(
                            "origin xyz `{text}` is not three finite numbers"
                        )))
                    }
                }
            }
            out.entry(link_name.to_string())
                .or_default()
                .push(CollisionSphere {
                    name: collision.attribute("name").map(str::to_string),
                    xyz,
                    radius,
                    line,
                });
        }
    }
    Ok(out)
}

/// The robot as a tree: each link's index by name, its children (joints), one root link.
struct Tree<'a> {
    links: HashMap<&'a str, usize>,
    children: Vec<Vec<usize>>,
    root: usize,
}

impl<'a> Tree<'a> {
    /// Every joint between existing links, one parent a link, one link without: the root.
    fn of(robot: &'a urdf_rs::Robot, reader: &Reader) -> Result<Self, ModelError> {
        let links: HashMap<&str, usize> = (robot.links.iter().enumerate())
            .map(|(i, l)| (l.name.as_str(), i))
            .collect();
        let mut parent_joint: Vec<Option<usize>> = vec![None; robot.links.len()];
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); robot.links.len()];
        for (j, joint) in robot.joints.iter().enumerate() {
            let (p, c) = joint_links(robot, joint, &links, &parent_joint, reader)?;
            check_joint_type(joint, reader)?;
            parent_joint[c] = Some(j);
            children[p].push(j);
        }
        if robot.links.is_empty() {
            return Err(reader.fail(
                "URDF: <robot> has no <link>: a robot needs at least one".into(),
                Some(reader.robot_line),
            ));
        }
        let roots: Vec<usize> = (0..robot.links.len())
            .filter(|&l| parent_joint[l].is_none())
            .collect();
        let root = match roots[..] {
            [r] => r,
            [] => {
                return Err(reader.fail(
                    "URDF: every link has a parent joint: the joints form a cycle".into(),
                    None,
                ))
            }
            _ => {
                let names: Vec<&str> = (roots.iter())
                    .map(|&r| robot.links[r].name.as_str())
                    .collect();
                return Err(reader.fail(
                    format!(
                        "URDF: {} links have no parent joint ({}); a tree has one root",
                        names.len(),
                        names.join(", ")
                    ),
                    reader.link_line(names[1]),
                ));
            }
        };
        Ok(Tree {
            links,
            children,
            root,
        })
    }
}

/// A joint's parent and child links: both exist, and the child has no other parent.
fn joint_links(
    robot: &urdf_rs::Robot,
    joint: &urdf_rs::Joint,
    links: &HashMap<&str, usize>,
    parent_joint: &[Option<usize>],
    reader: &Reader,
) -> Result<(usize, usize), ModelError> {
    let (line, name) = (reader.joint_line(&joint.name), &joint.name);
    let Some(&p) = links.get(joint.parent.link.as_str()) else {
        return Err(reader.fail(
            format!(
                "URDF: joint `{name}`: parent link `{}` does not exist",
                joint.parent.link
            ),
            line,
        ));
    };
    let Some(&c) = links.get(joint.child.link.as_str()) else {
        return Err(reader.fail(
            format!(
                "URDF: joint `{name}`: child link `{}` does not exist",
                joint.child.link
            ),
            line,
        ));
    };
    if let Some(other) = parent_joint[c] {
        return Err(reader.fail(
            format!(
                "URDF: link `{}` has two parents (joints `{}` and `{name}`); a tree has one",
                joint.child.link, robot.joints[other].name
            ),
            line,
        ));
    }
    Ok((p, c))
}

/// Only revolute, continuous, prismatic and fixed joints.
fn check_joint_type(joint: &urdf_rs::Joint, reader: &Reader) -> Result<(), ModelError> {
    let (line, name) = (reader.joint_line(&joint.name), &joint.name);
    use urdf_rs::JointType::*;
    match joint.joint_type {
        Revolute | Continuous | Prismatic | Fixed => {}
        ref other => {
            return Err(reader.fail(
                format!(
                    "URDF: joint `{name}` is {}; only revolute, continuous, prismatic and fixed joints are supported inside the tree (a free root: the floating-base option)",
                    format!("{other:?}").to_lowercase()
                ),
                line,
            ));
        }
    }
    Ok(())
}

/// The spec being written, with the source line of each frame and body, and each link's
/// frame (`None`: the world, or not reached yet).
struct Frames {
    spec: ModelSpec,
    frame_lines: Vec<Option<usize>>,
    body_lines: HashMap<usize, Option<usize>>,
    link_frame: Vec<Option<usize>>,
}

impl Frames {
    fn new(spec: ModelSpec, links: usize) -> Self {
        Frames {
            spec,
            frame_lines: Vec::new(),
            body_lines: HashMap::new(),
            link_frame: vec![None; links],
        }
    }

    /// A frame of one primitive, from `line`.
    fn push(
        &mut self,
        name: String,
        parent: Option<String>,
        (kind, value): (PrimitiveKind, Value),
        line: Option<usize>,
    ) {
        self.spec.frames.push(FrameSpec {
            name,
            parent,
            primitives: vec![Primitive { kind, value }],
            mass: None,
            com: None,
            inertia: None,
        });
        self.frame_lines.push(line);
    }

    /// The model, its problems given the lines of the frames, bodies and joints at fault.
    fn validate(self, reader: &Reader) -> Result<Model, ModelError> {
        let Frames {
            spec,
            frame_lines,
            body_lines,
            ..
        } = self;
        validate(&spec).map_err(|problems| ModelError {
            source_name: reader.source_name.clone(),
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
                        Site::VariableSettings { name } => reader.joint_line(name),
                        _ => None,
                    };
                    Problem { line, ..p }
                })
                .collect(),
        })
    }
}

/// The root link's frame: none for a root called `world` (ROS's convention for a robot
/// bolted to the ground: its children hang off our world), six variables before it for a
/// floating base, else a constant frame at the origin.
fn root_frames(
    out: &mut Frames,
    robot: &urdf_rs::Robot,
    tree: &Tree,
    options: UrdfOptions,
    reader: &Reader,
) -> Result<(), ModelError> {
    let root_name = robot.links[tree.root].name.clone();
    let line = reader.link_line(&root_name);
    if root_name == "world" {
        let inertial = &robot.links[tree.root].inertial;
        if inertial.mass.value != 0.0 || options.floating_base {
            return Err(reader.fail(
                "URDF: the root link is `world`, the fixed ground: it can carry no mass and take no floating base".into(),
                line,
            ));
        }
        return Ok(());
    }
    if options.floating_base {
        let mut parent = None;
        for (k, (var, kind)) in FLOATING_BASE.iter().enumerate() {
            if reader.joint_lines.contains_key(*var) {
                return Err(reader.fail(
                    format!("URDF: joint `{var}` clashes with the floating base's variable of that name"),
                    reader.joint_line(var),
                ));
            }
            let name = if k == 5 {
                root_name.clone()
            } else {
                var.to_string()
            };
            let motion = (*kind, Value::Variable(var.to_string()));
            out.push(name.clone(), parent, motion, line);
            parent = Some(name);
        }
    } else {
        let origin = (PrimitiveKind::Tx, Value::Constant(0.0));
        out.push(root_name, None, origin, line);
    }
    out.link_frame[tree.root] = Some(out.spec.frames.len() - 1);
    Ok(())
}

/// A joint's chain of frames (its origin, then its motion about its axis), the last one its
/// child link's; a moving joint's variable with its damping and limits, and an input on it.
fn joint_frames(
    out: &mut Frames,
    robot: &urdf_rs::Robot,
    joint: &urdf_rs::Joint,
    tree: &Tree,
    options: UrdfOptions,
    reader: &Reader,
) -> Result<(), ModelError> {
    let line = reader.joint_line(&joint.name);
    let parent_link = tree.links[joint.parent.link.as_str()];
    let child_link = tree.links[joint.child.link.as_str()];
    let mut chain = origin_chain(joint, reader)?;
    if joint.joint_type != urdf_rs::JointType::Fixed {
        let value = match &joint.mimic {
            Some(_) if !options.independent_mimics => Value::Mimic(mimic_of(robot, joint, reader)?),
            _ => {
                actuate(&mut out.spec, joint, reader.efforts.contains(&joint.name));
                Value::Variable(joint.name.clone())
            }
        };
        chain.extend(axis_chain(joint, value, reader)?);
    }
    if chain.is_empty() {
        chain.push((PrimitiveKind::Tx, Value::Constant(0.0)));
    }
    let mut parent = out.link_frame[parent_link].map(|f| out.spec.frames[f].name.clone());
    let last = chain.len() - 1;
    for (i, motion) in chain.into_iter().enumerate() {
        let name = if i == last {
            robot.links[child_link].name.clone()
        } else {
            joint_piece_name(&joint.name, i + 1, tree)
        };
        out.push(name.clone(), parent, motion, line);
        parent = Some(name);
    }
    out.link_frame[child_link] = Some(out.spec.frames.len() - 1);
    Ok(())
}

/// The name of piece `k` of a joint's chain before its child link: `joint#k`, the `#` marking
/// a frame the loader made (no link of the file is named so; another `#` in the rare file
/// whose link takes that name).
fn joint_piece_name(joint: &str, k: usize, tree: &Tree) -> String {
    let mut name = format!("{joint}#{k}");
    while tree.links.contains_key(name.as_str()) {
        name.push('#');
    }
    name
}

/// `<origin xyz rpy>`: `tx ty tz` (the non-zero ones), then `rz(yaw) ry(pitch) rx(roll)`.
fn origin_chain(
    joint: &urdf_rs::Joint,
    reader: &Reader,
) -> Result<Vec<(PrimitiveKind, Value)>, ModelError> {
    let xyz = joint.origin.xyz.0;
    let rpy = joint.origin.rpy.0;
    if xyz.iter().chain(rpy.iter()).any(|x| !x.is_finite()) {
        return Err(reader.fail(
            format!("URDF: joint `{}`: origin is not finite", joint.name),
            reader.joint_line(&joint.name),
        ));
    }
    let translations = [PrimitiveKind::Tx, PrimitiveKind::Ty, PrimitiveKind::Tz]
        .into_iter()
        .zip(xyz);
    let rotations = [
        (PrimitiveKind::Rz, rpy[2]),
        (PrimitiveKind::Ry, rpy[1]),
        (PrimitiveKind::Rx, rpy[0]),
    ];
    Ok(translations
        .chain(rotations)
        .filter(|&(_, x)| x != 0.0)
        .map(|(kind, x)| (kind, Value::Constant(x)))
        .collect())
}

/// The motion about (or along) `<axis>`: `rk(q)`/`tk(q)` when the axis is `+e_k`, else
/// `rz(α) ry(β)` turning `e_z` onto the axis, `rz(q)`/`tz(q)`, and `ry(−β) rz(−α)` back.
fn axis_chain(
    joint: &urdf_rs::Joint,
    variable: Value,
    reader: &Reader,
) -> Result<Vec<(PrimitiveKind, Value)>, ModelError> {
    let a = joint.axis.xyz.0;
    let norm = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    if !(norm.is_finite() && norm > 0.0) {
        return Err(reader.fail(
            format!(
                "URDF: joint `{}`: axis [{} {} {}] is zero or not finite",
                joint.name, a[0], a[1], a[2]
            ),
            reader.joint_line(&joint.name),
        ));
    }
    let a = a.map(|x| x / norm);
    let prismatic = joint.joint_type == urdf_rs::JointType::Prismatic;
    let constant = |kind, x: f64| (kind, Value::Constant(x));
    let mut chain = Vec::new();
    match (0..3).find(|&k| a[k] == 1.0) {
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
    Ok(chain)
}

/// A mimic joint's motion, `multiplier·q + offset` of the variable of the joint it follows
/// (through a chain of mimics, the maps composed), with its own `<dynamics damping>`. The
/// joint followed must exist and move; a cycle of mimics is refused.
fn mimic_of(
    robot: &urdf_rs::Robot,
    joint: &urdf_rs::Joint,
    reader: &Reader,
) -> Result<MimicSpec, ModelError> {
    let by_name = |name: &str| robot.joints.iter().find(|j| j.name == name);
    let line = reader.joint_line(&joint.name);
    let (mut multiplier, mut offset) = (1.0, 0.0);
    let mut at = joint;
    let mut seen = vec![joint.name.as_str()];
    while let Some(m) = &at.mimic {
        let Some(leader) = by_name(&m.joint) else {
            return Err(reader.fail(
                format!(
                    "URDF: joint `{}` mimics joint `{}`, which the file does not have",
                    at.name, m.joint
                ),
                reader.joint_line(&at.name).or(line),
            ));
        };
        if seen.contains(&leader.name.as_str()) {
            return Err(reader.fail(
                format!(
                    "URDF: the mimic joints {} follow one another in a cycle",
                    seen.iter()
                        .map(|n| format!("`{n}`"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
                line,
            ));
        }
        if leader.joint_type == urdf_rs::JointType::Fixed {
            return Err(reader.fail(
                format!(
                    "URDF: joint `{}` mimics joint `{}`, which is fixed: a mimic follows a moving joint",
                    at.name, leader.name
                ),
                reader.joint_line(&at.name).or(line),
            ));
        }
        // x_at = m·x_leader + o, and x = multiplier·x_at + offset.
        let (m_at, o_at) = (m.multiplier.unwrap_or(1.0), m.offset.unwrap_or(0.0));
        offset += multiplier * o_at;
        multiplier *= m_at;
        seen.push(&leader.name);
        at = leader;
    }
    Ok(MimicSpec {
        variable: at.name.clone(),
        multiplier,
        offset,
        damping: joint.dynamics.as_ref().map_or(0.0, |d| d.damping),
    })
}

/// A moving joint's variable (its damping, and limits unless continuous), and an input on
/// it named after it, with ±effort as its limits when the URDF gives an effort (`effort_given`;
/// 0 is a joint that exerts none): every joint is actuated.
fn actuate(spec: &mut ModelSpec, joint: &urdf_rs::Joint, effort_given: bool) {
    let mut settings = VariableSpec {
        name: joint.name.clone(),
        ..VariableSpec::default()
    };
    if let Some(d) = &joint.dynamics {
        if d.damping != 0.0 {
            settings.damping = Some(d.damping);
        }
    }
    if joint.joint_type != urdf_rs::JointType::Continuous {
        let l = &joint.limit;
        if l.lower != 0.0 || l.upper != 0.0 {
            settings.limits = Some([l.lower, l.upper]);
        }
    }
    let effort = joint.limit.effort;
    spec.inputs.push(InputSpec {
        name: joint.name.clone(),
        variable: Some(joint.name.clone()),
        // `0.0 - effort`, not `-effort`: an effort of 0 gives [0, 0], not [-0, 0].
        limits: effort_given.then_some([0.0 - effort, effort]),
    });
    spec.variables.push(settings);
}

/// Bodies: each link's `<inertial>` origin and tensor, turned into the link's axes, on its
/// frame. Problems with a body point at its `<link>`.
fn bodies(out: &mut Frames, robot: &urdf_rs::Robot, reader: &Reader) {
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
        let Some(f) = out.link_frame[l] else { continue };
        out.body_lines.insert(f, reader.link_line(&link.name));
        let frame = &mut out.spec.frames[f];
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

/// Whether an element is one the dynamics does not use, with all it holds: a child of
/// `<robot>` other than `<link>` and `<joint>` (`<gazebo>`, `<transmission>`, `<material>`,
/// `<ros2_control>`, …; urdfdom and Pinocchio ignore `<gazebo>` too) or a link's `<visual>`
/// and `<collision>` (shapes, which the dynamics never reads). A Gazebo block's nameless
/// `<material>` or a visual's empty `<texture/>` is then not the robot's problem.
fn unmodelled(node: &roxmltree::Node) -> bool {
    let tag = node.tag_name().name();
    match node.parent_element().map(|p| p.tag_name().name()) {
        Some("robot") => !matches!(tag, "link" | "joint"),
        Some("link") => matches!(tag, "visual" | "collision"),
        _ => false,
    }
}

/// Whether `node` lies in an [`unmodelled`] element.
fn set_aside(node: &roxmltree::Node) -> bool {
    node.ancestors().any(|a| a.is_element() && unmodelled(&a))
}

/// `text` with the [`unmodelled`] elements blanked out (every character but line breaks a
/// space, so lines keep their numbers): what urdf-rs reads.
fn modelled_text(text: &str, root: roxmltree::Node) -> String {
    let blanked: Vec<std::ops::Range<usize>> = root
        .descendants()
        .filter(|n| n.is_element() && unmodelled(n))
        .map(|n| n.range())
        .collect();
    let mut ranges = blanked.iter().peekable();
    text.char_indices()
        .map(|(i, c)| {
            while ranges.peek().is_some_and(|r| r.end <= i) {
                ranges.next();
            }
            let inside = ranges.peek().is_some_and(|r| r.contains(&i));
            if inside && c != '\n' {
                ' '
            } else {
                c
            }
        })
        .collect()
}

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
        let skipped = set_aside;
        for node in part.descendants().filter(|n| n.is_element() && !skipped(n)) {
            for (attribute, count) in NUMERIC {
                let Some(text) = node.attribute(attribute) else {
                    continue;
                };
                let numbers: Vec<&str> = text.split_whitespace().collect();
                let parsed: Vec<Option<f64>> = numbers.iter().map(|x| x.parse().ok()).collect();
                if let Some(problem) = bound_problem(attribute, &parsed) {
                    return Err((
                        format!(
                            "URDF: {owner}: <{} {attribute}=\"{text}\"> {problem}",
                            node.tag_name().name()
                        ),
                        line_at(node.range().start),
                    ));
                }
                if numbers.len() != count || parsed.iter().any(Option::is_none) {
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

/// What is wrong with an attribute's numbers beyond their count: NaN anywhere; an `effort`
/// or `velocity` (a bound on the joint's force and speed) that is not finite or is negative.
fn bound_problem(attribute: &str, numbers: &[Option<f64>]) -> Option<&'static str> {
    let numbers = numbers.iter().flatten();
    if numbers.clone().any(|x| x.is_nan()) {
        return Some("is not a number");
    }
    let bound = matches!(attribute, "effort" | "velocity");
    (bound && numbers.clone().any(|&x| !x.is_finite() || x < 0.0))
        .then_some("must be a finite number ≥ 0 (the joint's largest force or torque, or speed)")
}

/// What urdf-rs requires of an element, by tag and parent tag (`""`: any parent): its
/// attributes, and the children it must have. urdf-rs says only "missing field `mass`" when
/// one is absent; checked first, the message names the link or joint and the line.
const REQUIRED: [(&str, &str, &[&str], &[&str]); 10] = [
    ("link", "robot", &["name"], &[]),
    ("joint", "robot", &["name", "type"], &["parent", "child"]),
    ("inertial", "link", &[], &["mass", "inertia"]),
    ("mass", "inertial", &["value"], &[]),
    (
        "inertia",
        "inertial",
        &["ixx", "ixy", "ixz", "iyy", "iyz", "izz"],
        &[],
    ),
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
    for node in root
        .descendants()
        .filter(|n| n.is_element() && !set_aside(n))
    {
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

/// Reads a model file: as URDF (with `options`) when it ends in `.urdf` or its text is XML
/// (a URDF saved as `.xml`), else as TOML (where `options.floating_base` is an error: a TOML
/// model says its own variables).
pub fn from_file(path: impl AsRef<Path>, options: UrdfOptions) -> Result<Model, ModelError> {
    let path = path.as_ref();
    let shown = path.display().to_string();
    let text = crate::source::read_model_file(path)?;
    let xml = text
        .trim_start_matches('\u{feff}')
        .trim_start()
        .starts_with('<');
    if xml
        || path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("urdf"))
    {
        return from_urdf_str(&text, Some(&shown), options);
    }
    if options.floating_base {
        return Err(ModelError::single(
            Some(shown),
            "a floating base is added to URDF models only; a TOML model declares its own base variables".into(),
            None,
        ));
    }
    if options.collision_spheres {
        return Err(ModelError::single(
            Some(shown),
            "collision spheres are read from URDF models only; a TOML model declares its contacts as [[contact]] tables".into(),
            None,
        ));
    }
    crate::toml_format::from_toml_str(&text, Some(&shown))
}

/// Each `<collision>` sphere of a link as a contact on it (`UrdfOptions::collision_spheres`):
/// at the link's frame when its origin is, else on constant child frames to the origin's
/// offset (a sphere's orientation is immaterial). Named by the collision's `name`, else by
/// its link (`link_2` … for a link's second and later spheres). They touch the ground only:
/// a robot's neighbouring links overlap by design, and self-collision is not modelled.
/// A robot without any is an error: asking for its spheres would otherwise add nothing unsaid.
fn collision_spheres(
    out: &mut Frames,
    robot: &urdf_rs::Robot,
    reader: &Reader,
) -> Result<(), ModelError> {
    if reader.spheres.is_empty() {
        return Err(reader.fail(
            format!(
                "URDF: robot `{}` has no <collision><sphere> to make contacts of; add contact points on its frames instead (--contact FRAME[:RADIUS])",
                robot.name
            ),
            Some(reader.robot_line),
        ));
    }
    for (l, link) in robot.links.iter().enumerate() {
        let (Some(f), Some(spheres)) = (out.link_frame[l], reader.spheres.get(&link.name)) else {
            continue;
        };
        let link_frame = out.spec.frames[f].name.clone();
        for (k, sphere) in spheres.iter().enumerate() {
            let name = match sphere.name.as_deref() {
                Some(n) if !n.is_empty() => n.to_string(),
                _ if k == 0 => link.name.clone(),
                _ => format!("{}_{}", link.name, k + 1),
            };
            let offsets = [PrimitiveKind::Tx, PrimitiveKind::Ty, PrimitiveKind::Tz]
                .into_iter()
                .zip(sphere.xyz)
                .filter(|&(_, x)| x != 0.0);
            let mut parent = link_frame.clone();
            for (i, (kind, x)) in offsets.enumerate() {
                let frame = format!("{name}#sphere{}", i + 1);
                let line = Some(sphere.line);
                out.push(
                    frame.clone(),
                    Some(parent),
                    (kind, Value::Constant(x)),
                    line,
                );
                parent = frame;
            }
            out.spec.contacts.contacts.push(ContactSpec {
                name: Some(name),
                frame: parent,
                radius: Some(sphere.radius),
                friction: None,
                collide: Some(false),
            });
        }
    }
    Ok(())
}
