// A mimic's settings are multiplier, offset and damping.
tree_mech::tree_model! {
    struct Bad;
    frame a = rx(q) {
        frame b = ry(mimic(q, gain = 2.0)) { mass = 1.0; }
    }
}

fn main() {}
