"""brachycal nwire: calibrate (default), nwire segment."""
