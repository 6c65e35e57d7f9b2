"""The world: rig model and presets, coverage through the mirrors, procedural objects with
their exact ground truth.  numpy / trimesh only; never imports the simulator or recon."""
