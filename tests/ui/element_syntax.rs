// Settings that do not belong to an element, or values of the wrong type.
tree_mech::tree_model! {
    struct Bad;
    frame arm = rx(q) { frame tip = tz(-1.0) { mass = 1.0; } }
    frame hook = tz(1.0);
    variable q { motion = 3.0; }
    constraint a = distance(tip, hook) { length = "long"; color = 1.0; }
    spring(tip, hook) { stiffness = stiff; }
    damper(tip, hook) { damping = 1.0; rest = 0.1; }
}

fn main() {}
