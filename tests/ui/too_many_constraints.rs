// Two constraint equations on one dynamic variable.
tree_mech::tree_model! {
    struct Bad;
    frame arm = rx(q) { frame tip = tz(-1.0) { mass = 1.0; } }
    frame hook = tz(1.0);
    constraint rod = point(tip, hook) { axes = yz; }
}

fn main() {}
