"""``brachycal robot``: the robot's own geometry identified from a calibration protocol
(``robot identify touches``: touches of fixed points by a tool on the flange)."""
