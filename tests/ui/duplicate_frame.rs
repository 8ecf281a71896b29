tree_mech::tree_model! {
    struct Bad;
    frame a = rx(q) {
        frame link = tz(1.0) { mass = 1.0; }
        frame link = tz(2.0) { mass = 1.0; }
    }
}

fn main() {}
