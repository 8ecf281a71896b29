tree_mech::tree_model! {
    struct Bad;
    frame a = rw(q) { mass = 1.0; }
}

fn main() {}
