"""Ground-truth MuJoCo tabletop world: objects, cluttered scenes, robot, RGB-D rendering and the sim node."""
