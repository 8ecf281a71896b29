// Every element problem at once, each at its token.
tree_mech::tree_model! {
    struct Bad;
    frame arm = rx(q) { frame tip = tz(-1.0) { mass = 1.0; } }
    frame hook = tz(1.0);
    variable len { kinematic = true; }
    constraint a = distance(tip, nowhere) { length = len; }
    constraint b = distance(tip, tip) { length = 1.0; }
    constraint c = rope(tip, hook) { length = 1.0; }
    constraint d = plane(hook, tip) { normal = [0.0, 0.0, 0.0]; length = 1.0; }
    constraint e = point(hook, tip) { axes = "xw"; }
    constraint e = distance(hook, tip) { length = -2.0; }
    constraint g = distance(hook, tip) { length = unknown_len; }
    constraint h = distance(hook, tip) {}
    spring(hook, tip) { stiffness = -1.0; rest = -0.2; }
    spring(len) { stiffness = 1.0; }
    damper(hook, tip) { damping = -0.5; }
}

fn main() {}
