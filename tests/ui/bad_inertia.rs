// A body no rigid body can have: every problem at its token (each body a rigid body of its
// own, moved by its own variable).
tree_mech::tree_model! {
    struct Bad;
    frame a = rx(q) {
        frame b = ry(r) { mass = 1.0; inertia = [1.0, 1.0, 3.0]; }
        frame c = rz(s) { mass = 1.0; com = [0.0, 0.1, 0.0]; inertia = [1.0, 1.0, 1.0, 2.0, 0.0, 0.0]; }
        frame d = tz(3.0) { mass = 1.0; inertia = [1.0, 1.0]; }
    }
}

fn main() {}
