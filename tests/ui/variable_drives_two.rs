tree_mech::tree_model! {
    struct Bad;
    frame a = rx(q) {
        frame b = ry(q) {
            frame c = tz(1.0) { mass = 1.0; }
        }
    }
}

fn main() {}
