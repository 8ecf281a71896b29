// A body no rigid body can have: every problem at its token.
tree_mech::tree_model! {
    struct Bad;
    frame a = rx(q) {
        frame b = tz(1.0) { mass = 1.0; inertia = [1.0, 1.0, 3.0]; }
        frame c = tz(2.0) { mass = 1.0; com = [0.0, 0.1, 0.0]; inertia = [1.0, 1.0, 1.0, 2.0, 0.0, 0.0]; }
        frame d = tz(3.0) { mass = 1.0; inertia = [1.0, 1.0]; }
    }
}

fn main() {}
