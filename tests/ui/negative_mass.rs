tree_mech::tree_model! {
    struct Bad;
    frame a = tz(q) { mass = -2.0; }
}

fn main() {}
