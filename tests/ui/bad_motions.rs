// Problems with prescribed variables, each at the variable it concerns.
tree_mech::tree_model! {
    struct Bad;
    frame arm = rx(q) { frame tip = tz(-1.0) { mass = 1.0; } }
    frame hook = ty(slide) { frame hook_z = tz(1.0); }
    frame other = tx(push) { frame away = ty(far) { frame spun = rz(whirl); } }
    variable q { motion = sine(amplitude = 0.1, frequency = 1.0); }
    variable slide { kinematic = true; damping = 0.3; samples = [[0.0, 0.0], [0.0, 1.0]]; }
    variable push { kinematic = true; motion = sine(offset = 0.0, speed = 2.0); }
    variable far { kinematic = true; samples = [[0.0, 0.0], [1.0, 1e999]]; }
    variable whirl { kinematic = true; motion = sine(amplitude = 1.0, frequency = 1e155); }
    constraint one = distance(tip, hook_z) { length = 1.0; }
    constraint two = point(tip, other) { axes = x; }
}

fn main() {}
