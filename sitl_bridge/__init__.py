"""A pure-Python simulated multirotor that speaks MAVLink 2 as PX4 (``sitl_bridge.px4``) or ArduPilot Copter
(``sitl_bridge.ardupilot``) does, over UDP, TCP or an in-memory link (docs/sitl.md)."""
