"""ARM amodal reconstruction: four-channel grids, 3D network with stability and connectivity priors, simulation-ready meshes."""
