// Problems with inputs, each at the token at fault.
tree_mech::tree_model! {
    struct Bad;
    frame slide = tx(x) { mass = 1.0; frame hand = ty(k); }
    variable k { kinematic = true; }
    input push = x { limits = [1.0]; }
    input kick = k;
    input ghost = nowhere { limits = [2.0, 1.0]; }
    input push = x { speed = 2.0; }
}

fn main() {}
