"""What the simulators draw: the tile world, the linear system, the planar robot."""
