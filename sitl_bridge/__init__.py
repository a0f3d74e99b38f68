"""A pure-Python SITL-like multirotor that speaks PX4-flavoured MAVLink 2."""
