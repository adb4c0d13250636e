"""ARM amodal reconstruction: four-channel grids, a 3D network trained with stability and
connectivity priors, and simulation-ready meshes."""
