pub use tree_model;
