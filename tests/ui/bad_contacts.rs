// Every contact problem at once, each at its token.
tree_mech::tree_model! {
    struct Bad;
    frame x = tx(x) { frame ball = tz(z) { mass = 1.0; } }
    ground { friction = -0.5; normal = [0.0, 0.0, 0.0]; }
    contact a = sphere(nowhere) { radius = 0.1; }
    contact b = sphere(ball) { radius = -0.1; friction = -1.0; }
    contact c = sphere(world) { radius = 0.1; }
    contact d = sphere(ball) { size = 0.1; collide = 2.0; }
    constraint s = distance(ball, ball) { length = 1.0; slack = maybe; }
}

fn main() {}
