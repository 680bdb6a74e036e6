"""The plant models controllers carry (what a controller assumes, never the simulator)."""
