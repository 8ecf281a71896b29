//! URDF: what each element becomes, and every unsupported or broken input as a one-line
//! error naming the element and its line.

use tree_model::{from_file, from_urdf_str, Joint, PrimitiveKind, UrdfOptions};

const FIXED: UrdfOptions = UrdfOptions {
    floating_base: false,
    independent_mimics: false,
    collision_spheres: false,
};

fn error_of(text: &str) -> String {
    match from_urdf_str(text, Some("r.urdf"), FIXED) {
        Ok(_) => panic!("should be rejected:\n{text}"),
        Err(e) => e.to_string(),
    }
}

/// A two-link arm; `joint2` is spliced in.
fn arm(joint2: &str) -> String {
    format!(
        r#"<robot name="arm">
  <link name="base"/>
  <link name="upper">
    <inertial>
      <origin xyz="0 0 0.2" rpy="0.1 0.2 0.3"/>
      <mass value="2.0"/>
      <inertia ixx="0.03" ixy="0.001" ixz="0" iyy="0.025" iyz="0" izz="0.01"/>
    </inertial>
  </link>
  <link name="lower"><inertial><mass value="1.0"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.005"/></inertial></link>
  <joint name="joint1" type="revolute">
    <parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/>
    <limit lower="-1" upper="2" effort="10" velocity="1"/>
    <dynamics damping="0.5"/>
  </joint>
{joint2}
</robot>"#
    )
}

const GOOD_JOINT2: &str = r#"  <joint name="joint2" type="prismatic">
    <parent link="upper"/><child link="lower"/>
    <origin xyz="0.1 0 0.4" rpy="0 1.5707963267948966 0"/>
    <axis xyz="0 -1 1"/>
  </joint>"#;

#[test]
fn joints_become_chains_of_primitives_and_links_bodies() {
    let m = from_urdf_str(&arm(GOOD_JOINT2), Some("r.urdf"), FIXED).unwrap();
    assert_eq!(m.name, "arm");
    let names: Vec<&str> = m.variables.iter().map(|v| v.name.as_str()).collect();
    assert_eq!(names, ["joint1", "joint2"]);
    let j1 = &m.variables[0];
    assert_eq!(j1.damping, 0.5);
    assert_eq!(j1.limits, Some([-1.0, 2.0]));
    // joint1: tz(0.1), then rz(joint1) — the axis is +z — as link `upper`.
    let upper = m.frame_index("upper").unwrap();
    assert_eq!(m.frames[upper].primitive, PrimitiveKind::Rz);
    assert_eq!(m.frames[upper].joint, Joint::Variable(0));
    // The inertial's rotation is applied: the tensor in link axes is not diagonal, and the
    // centre of mass is the inertial origin.
    let body = m.frames[upper].mass.unwrap();
    assert_eq!(body.com, [0.0, 0.0, 0.2]);
    assert!(body.diagonal().is_none());
    let trace: f64 = (0..3).map(|k| body.inertia[k][k]).sum();
    assert!((trace - 0.065).abs() < 1e-15, "rotation keeps the trace");
    // joint2 on an oblique axis: prismatic along it, turned onto z and back, the last
    // frame is link `lower`.
    let driven = m.variables[1].frame.unwrap();
    assert_eq!(m.frames[driven].primitive, PrimitiveKind::Tz);
    assert_eq!(m.variables[1].limits, None, "no <limit>: none kept");
}

#[test]
fn a_floating_base_adds_six_variables_above_the_root() {
    let options = UrdfOptions {
        floating_base: true,
        ..Default::default()
    };
    let m = from_urdf_str(&arm(GOOD_JOINT2), None, options).unwrap();
    let names: Vec<&str> = m.variables.iter().map(|v| v.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "root_x",
            "root_y",
            "root_z",
            "root_yaw",
            "root_pitch",
            "root_roll",
            "joint1",
            "joint2"
        ]
    );
    let base = m.frame_index("base").unwrap();
    assert_eq!(m.frames[base].primitive, PrimitiveKind::Rx);
}

#[test]
fn unsupported_and_broken_urdf_is_named_with_its_line() {
    let cases: [(String, &str); 15] = [
        (
            arm(r#"  <joint name="joint2" type="floating"><parent link="upper"/><child link="lower"/></joint>"#),
            "r.urdf:18: URDF: joint `joint2` is floating; only revolute, continuous, prismatic and fixed joints",
        ),
        (
            arm(r#"  <joint name="joint2" type="planar"><parent link="upper"/><child link="lower"/><axis xyz="0 0 1"/></joint>"#),
            "r.urdf:18: URDF: joint `joint2` is planar",
        ),
        (
            arm(r#"  <joint name="joint2" type="revolute"><parent link="upper"/><child link="lower"/><mimic joint="joint0"/><limit lower="0" upper="1" effort="1" velocity="1"/></joint>"#),
            "r.urdf:18: URDF: joint `joint2` mimics joint `joint0`, which the file does not have",
        ),
        (
            arm(r#"  <joint name="joint2" type="revolute"><parent link="upper"/><child link="lower"/><mimic joint="joint3"/><limit lower="0" upper="1" effort="1" velocity="1"/></joint>
  <link name="tip"/>
  <joint name="joint3" type="fixed"><parent link="lower"/><child link="tip"/></joint>"#),
            "r.urdf:18: URDF: joint `joint2` mimics joint `joint3`, which is fixed: a mimic follows a moving joint",
        ),
        (
            arm(r#"  <joint name="joint2" type="revolute"><parent link="upper"/><child link="lower"/><mimic joint="joint3"/><limit lower="0" upper="1" effort="1" velocity="1"/></joint>
  <link name="tip"><inertial><mass value="0.1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.005"/></inertial></link>
  <joint name="joint3" type="revolute"><parent link="lower"/><child link="tip"/><mimic joint="joint2"/><limit lower="0" upper="1" effort="1" velocity="1"/></joint>"#),
            "r.urdf:18: URDF: the mimic joints `joint2`, `joint3` follow one another in a cycle",
        ),
        (
            "<robot name=\"lone\">\n  <link name=\"body\"/>\n</robot>".to_string(),
            "r.urdf:1: URDF: robot `lone` has no moving joint: fixed to the world it has nothing to simulate; give it a floating base (--floating-base)",
        ),
        (
            arm(r#"  <joint name="joint2" type="fixed"><parent link="upper"/><child link="hand"/></joint>"#),
            "r.urdf:18: URDF: joint `joint2`: child link `hand` does not exist",
        ),
        (
            arm(r#"  <joint name="joint2" type="fixed"><parent link="base"/><child link="upper"/></joint>"#),
            "r.urdf:18: URDF: link `upper` has two parents (joints `joint1` and `joint2`)",
        ),
        (
            arm(""),
            "URDF: 2 links have no parent joint (base, lower); a tree has one root",
        ),
        (
            arm(r#"  <joint name="joint2" type="fixed"><parent link="upper"/><child link="lower"/></joint>
  <joint name="joint3" type="fixed"><parent link="lower"/><child link="base"/></joint>"#),
            "URDF: every link has a parent joint: the joints form a cycle",
        ),
        (
            arm(r#"  <joint name="joint2" type="revolute"><parent link="upper"/><child link="lower"/><axis xyz="0 0 0"/><limit lower="0" upper="1" effort="1" velocity="1"/></joint>"#),
            "r.urdf:18: URDF: joint `joint2`: axis [0 0 0] is zero or not finite",
        ),
        (
            "<robot name=\"r\">\n  <link name=\"a\">\n  </lnk>\n</robot>".to_string(),
            "r.urdf:3: XML error",
        ),
        (
            arm(GOOD_JOINT2).replace(r#"<mass value="1.0"/>"#, r#"<mass value="heavy"/>"#),
            r#"r.urdf:10: URDF: link `lower`: <mass value="heavy"> must be a number"#,
        ),
        (
            arm(GOOD_JOINT2).replace(r#"<origin xyz="0.1 0 0.4""#, r#"<origin xyz="0.1 0""#),
            r#"r.urdf:20: URDF: joint `joint2`: <origin xyz="0.1 0"> must be 3 numbers"#,
        ),
        (
            // `lower` and a new link `hand` hold each other: a cycle apart from the root.
            arm(r#"  <link name="hand"/>
  <joint name="joint2" type="fixed"><parent link="lower"/><child link="hand"/></joint>
  <joint name="joint3" type="fixed"><parent link="hand"/><child link="lower"/></joint>"#),
            "URDF: link `lower` is not reachable from the root link `base`: its joints form a cycle",
        ),
    ];
    for (text, expected) in cases {
        let e = error_of(&text);
        assert!(e.contains(expected), "expected `{expected}` in:\n{e}");
        assert_eq!(e.lines().count(), 1, "one line: {e}");
    }
}

#[test]
fn a_body_no_rigid_body_can_have_is_named_at_its_link() {
    let text = arm(GOOD_JOINT2).replace(
        r#"<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.005"/>"#,
        r#"<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.05"/>"#,
    );
    let e = error_of(&text);
    assert!(
        e.contains("frame `lower`: inertia") && e.contains("triangle inequality"),
        "{e}"
    );
    assert!(e.starts_with("r.urdf:10:"), "the line of the <link>: {e}");
}

#[test]
fn from_file_reads_urdf_by_extension_and_refuses_a_floating_toml() {
    let dir = std::env::temp_dir().join(format!("tree-model-urdf-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let urdf = dir.join("arm.URDF");
    std::fs::write(&urdf, arm(GOOD_JOINT2)).unwrap();
    assert_eq!(from_file(&urdf, FIXED).unwrap().dof(), 2);
    let toml = dir.join("p.toml");
    std::fs::write(&toml, "[[frame]]\nname = \"a\"\nrx = \"q\"\nmass = 1.0\n").unwrap();
    let e = from_file(
        &toml,
        UrdfOptions {
            floating_base: true,
            ..Default::default()
        },
    )
    .unwrap_err();
    assert!(
        e.to_string()
            .contains("floating base is added to URDF models only"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn deep_or_attribute_heavy_xml_is_refused_before_parsing() {
    // urdf-rs recursed once per level and overflowed its stack at about 15 000.
    let deep = format!(
        "<robot name=\"r\">\n<link name=\"a\">\n{}{}</link></robot>",
        "<x>".repeat(15_000),
        "</x>".repeat(15_000)
    );
    let msg = error_of(&deep);
    assert!(
        msg.starts_with("r.urdf:3: XML nesting is deeper than the limit of 100"),
        "{msg}"
    );
    // roxmltree compares an element's attributes pairwise: 200 000 took half a minute.
    let attributes: String = (0..200_000).map(|k| format!(" a{k}=\"1\"")).collect();
    let msg = error_of(&format!(
        "<robot name=\"r\">\n<link name=\"a\"{attributes}/></robot>"
    ));
    assert!(
        msg.starts_with("r.urdf:2: XML element has 200001 attributes, more than the limit of 64"),
        "{msg}"
    );
}

#[test]
fn what_urdf_rs_requires_is_named_with_its_element_and_line() {
    let inertial = |body: &str| {
        format!(
            "<robot name=\"r\">\n<link name=\"base\"/>\n<link name=\"arm\"><inertial>{body}</inertial></link>\n\
             <joint name=\"j\" type=\"revolute\"><parent link=\"base\"/><child link=\"arm\"/></joint></robot>"
        )
    };
    let no_mass = inertial(r#"<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/>"#);
    assert_eq!(
        error_of(&no_mass),
        "r.urdf:3: URDF: link `arm`: <inertial> has no <mass>"
    );
    let no_izz = inertial(r#"<mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0"/>"#);
    assert_eq!(
        error_of(&no_izz),
        "r.urdf:3: URDF: link `arm`: <inertia> has no `izz` attribute"
    );
    let no_child = arm(r#"<joint name="joint2" type="revolute"><parent link="upper"/></joint>"#);
    assert!(
        error_of(&no_child).ends_with("URDF: joint `joint2`: <joint> has no <child>"),
        "{}",
        error_of(&no_child)
    );
    let no_velocity = arm(
        "<joint name=\"joint2\" type=\"revolute\"><parent link=\"upper\"/><child link=\"lower\"/>\n\
         <limit effort=\"1\"/></joint>",
    );
    let msg = error_of(&no_velocity);
    assert!(
        msg.contains(":19: URDF: joint `joint2`: <limit> has no `velocity` attribute"),
        "{msg}"
    );
    assert_eq!(
        error_of("<robot name=\"empty\">\n</robot>"),
        "r.urdf:1: URDF: <robot> has no <link>: a robot needs at least one"
    );
}

#[test]
fn reading_urdf_takes_time_linear_in_its_size() {
    // A chain of n links read in time linear in n: eight times the links take about eight
    // times as long, where a reader quadratic in n would take 64 times (an earlier one found
    // each element's line by rescanning the text). A complexity, not a speed: the bound of 20
    // is twice the ratio measured (about 10) and a third of the quadratic one, so the
    // machine's noise (in every one of three repeats) cannot decide it.
    let chain = |n: usize| {
        let mut s = String::from("<robot name=\"c\">\n<link name=\"l0\"/>\n");
        for k in 1..=n {
            s += &format!(
                "<link name=\"l{k}\"><inertial><mass value=\"1\"/><inertia ixx=\"1\" ixy=\"0\" ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"1\"/></inertial></link>\n\
                 <joint name=\"j{k}\" type=\"revolute\"><parent link=\"l{}\"/><child link=\"l{k}\"/><origin xyz=\"0 0 1\"/><axis xyz=\"1 0 0\"/></joint>\n",
                k - 1
            );
        }
        s + "</robot>"
    };
    let time = |n: usize| {
        let text = chain(n);
        let start = std::time::Instant::now();
        let model = from_urdf_str(&text, None, FIXED).unwrap();
        assert_eq!(model.dof(), n);
        start.elapsed().as_secs_f64()
    };
    let ratio = growth(time, 1_000);
    assert!(
        ratio < 20.0,
        "eight times the chain took {ratio:.1}× the time"
    );
}

/// The smallest of three ratios `time(8n) / time(n)` (the fastest repeat is the least noisy).
pub fn growth(time: impl Fn(usize) -> f64, n: usize) -> f64 {
    time(n); // warm up
    (0..3)
        .map(|_| time(8 * n) / time(n))
        .fold(f64::INFINITY, f64::min)
}

/// `joint2` as a revolute joint whose `<limit>` says `effort`.
fn with_effort(effort: &str) -> String {
    arm(&format!(
        r#"  <joint name="joint2" type="revolute">
    <parent link="upper"/><child link="lower"/>
    <axis xyz="1 0 0"/>
    <limit lower="-1" upper="1" effort="{effort}" velocity="1"/>
  </joint>"#
    ))
}

#[test]
fn an_effort_limits_its_input_to_what_the_file_says_or_is_refused_with_its_line() {
    let limits = |text: &str| {
        let m = from_urdf_str(text, Some("r.urdf"), FIXED).unwrap();
        let u = m.inputs.iter().find(|u| u.name == "joint2").unwrap();
        u.limits
    };
    assert_eq!(limits(&with_effort("36")), Some([-36.0, 36.0]));
    // An effort of 0 is a joint that exerts none, not one without limits.
    assert_eq!(limits(&with_effort("0")), Some([0.0, 0.0]));
    // No effort said (no <limit> at all): no limits.
    assert_eq!(limits(&arm(GOOD_JOINT2)), None);
    for bad in ["nan", "NaN", "-5", "inf", "-inf"] {
        let e = error_of(&with_effort(bad));
        assert!(e.starts_with("r.urdf:21:"), "{bad}: {e}");
        assert!(e.contains("joint `joint2`"), "{bad}: {e}");
        assert!(
            e.contains("is not a number") || e.contains("must be a finite number ≥ 0"),
            "{bad}: {e}"
        );
    }
}

#[test]
fn the_loaders_frames_are_marked_and_never_take_a_links_name() {
    // joint1's chain: tz(0.1) as `joint1#1`, then rz(joint1) as link `upper`.
    let m = from_urdf_str(&arm(GOOD_JOINT2), Some("r.urdf"), FIXED).unwrap();
    let names: Vec<&str> = m.frames.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(&names[..3], ["base", "joint1#1", "upper"]);
    let made: Vec<&&str> = names.iter().filter(|n| n.contains('#')).collect();
    assert!(made
        .iter()
        .all(|n| n.starts_with("joint1#") || n.starts_with("joint2#")));
    // iCub's clash: joint `l_elbow` and a link `l_elbow_1` (the old `JOINT_k` names took it),
    // and a file whose link is literally named `joint1#1`.
    let clash = arm(GOOD_JOINT2)
        .replace("\"lower\"", "\"joint1_1\"")
        .replace("<link name=\"base\"/>", "<link name=\"base\"/><link name=\"joint1#1\"/>")
        .replace(
            "</robot>",
            "<joint name=\"j3\" type=\"fixed\"><parent link=\"base\"/><child link=\"joint1#1\"/></joint></robot>",
        );
    let m = from_urdf_str(&clash, Some("r.urdf"), FIXED).unwrap();
    for name in ["joint1_1", "joint1#1", "joint1#1#"] {
        assert!(m.frame_index(name).is_some(), "{name}");
    }
}

#[test]
fn what_the_dynamics_does_not_read_is_set_aside() {
    // A Gazebo block's nameless <material> (Talos, Tiago, HyQ, PR2), a visual's empty
    // <texture/> (iCub), an empty <geometry>, a <transmission>: none is the dynamics', and
    // urdfdom and Pinocchio load such files. The lines of what is read stay where they were.
    let extras = arm(GOOD_JOINT2).replace(
        "</robot>",
        "<gazebo reference=\"upper\"><material>Gazebo/Grey</material></gazebo>\n\
         <material name=\"skin\"><texture/></material>\n\
         <transmission name=\"t\"><type>x</type></transmission></robot>",
    );
    let extras = extras.replace(
        "<link name=\"base\"/>",
        "<link name=\"base\"><visual><geometry></geometry><material><texture/></material></visual>\
         <collision><geometry/></collision></link>",
    );
    let m = from_urdf_str(&extras, Some("r.urdf"), FIXED).unwrap();
    let plain = from_urdf_str(&arm(GOOD_JOINT2), Some("r.urdf"), FIXED).unwrap();
    assert_eq!(m.frames, plain.frames);
    // What is read is still checked, with its line.
    let bad = extras.replace("<mass value=\"1.0\"/>", "<mass value=\"x\"/>");
    assert_eq!(
        error_of(&bad),
        "r.urdf:10: URDF: link `lower`: <mass value=\"x\"> must be a number"
    );
}

/// A mimic joint follows the joint it names (`multiplier·q + offset`), through a chain of
/// mimics with the maps composed, with its own damping; it makes no variable and no input.
/// With `independent_mimics` (Pinocchio's default) each is a joint of its own.
#[test]
fn a_mimic_joint_follows_its_leader_through_a_chain() {
    let text = arm(
        r#"  <joint name="joint2" type="revolute"><parent link="upper"/><child link="lower"/><axis xyz="1 0 0"/><mimic joint="joint1" multiplier="2" offset="0.1"/><limit lower="0" upper="1" effort="1" velocity="1"/></joint>
  <link name="tip"><inertial><mass value="0.1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.005"/></inertial></link>
  <joint name="joint3" type="prismatic"><parent link="lower"/><child link="tip"/><axis xyz="0 1 0"/><mimic joint="joint2" multiplier="-1" offset="0.3"/><dynamics damping="0.7"/><limit lower="0" upper="1" effort="1" velocity="1"/></joint>"#,
    );
    let m = from_urdf_str(&text, None, FIXED).unwrap();
    assert_eq!(m.variables.len(), 1);
    assert_eq!(m.inputs.len(), 1);
    let mimic = |frame: &str| match m.frames[m.frame_index(frame).unwrap()].joint {
        Joint::Mimic(x) => (x.variable, x.multiplier, x.offset, x.damping),
        other => panic!("{frame}: {other:?}"),
    };
    assert_eq!(mimic("lower"), (0, 2.0, 0.1, 0.0));
    // joint3 = −(2 q + 0.1) + 0.3.
    let (v, k, o, c) = mimic("tip");
    assert_eq!((v, k, c), (0, -2.0, 0.7));
    assert!((o - 0.2).abs() < 1e-15);
    let independent = UrdfOptions {
        independent_mimics: true,
        ..FIXED
    };
    let m = from_urdf_str(&text, None, independent).unwrap();
    assert_eq!(m.variables.len(), 3);
    assert!(m.frames.iter().all(|f| !matches!(f.joint, Joint::Mimic(_))));
}
