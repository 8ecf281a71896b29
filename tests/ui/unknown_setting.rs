tree_mech::tree_model! {
    struct Bad;
    frame a = tz(q) { mass = 1.0; }
    variable q { q0 = 1.0; velocity = 2.0; }
    variable ghost { q0 = 1.0; }
}

fn main() {}
