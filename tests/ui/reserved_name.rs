tree_mech::tree_model! {
    struct Bad;
    frame a = tz(q0) { mass = 1.0; }
}

fn main() {}
