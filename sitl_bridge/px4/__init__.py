"""The PX4 personality of the simulated vehicle: commander's arming and mode rules, offboard, orbit, the failsafes,
the geofence, Mission mode and PX4's side of the mission protocol (:class:`sitl_bridge.px4.autopilot.Px4Autopilot`).
"""
