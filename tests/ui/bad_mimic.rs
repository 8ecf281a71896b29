// A mimic naming a variable no frame drives, and one with a negative damping: each named at
// the mimic.
tree_mech::tree_model! {
    struct Bad;
    frame a = rx(q) {
        frame b = ry(mimic(qq, multiplier = -1.0)) {
            frame c = tz(1.0) { mass = 1.0; }
        }
        frame d = rz(mimic(q, offset = 0.5, damping = -2.0)) { mass = 1.0; }
    }
}

fn main() {}
