"""demtrack: geospatial trajectories from calibrated cameras and a DEM."""
