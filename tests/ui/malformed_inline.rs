tree_mech::tree_model! {
    struct Bad;
    frame a rx(q) { mass = 1.0; }
}

fn main() {}
