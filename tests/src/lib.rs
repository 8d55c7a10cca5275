//! Hardware-in-loop scenario runner.
