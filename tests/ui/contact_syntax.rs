// A contact shape the macro does not know is an error at the shape.
tree_mech::tree_model! {
    struct Bad;
    frame ball = tz(z) { mass = 1.0; }
    contact a = cube(ball) { radius = 0.1; }
}

fn main() {}
