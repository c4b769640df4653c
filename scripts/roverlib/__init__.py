"""Python tools of rover_loop_fusion: simulated and real-data scenarios, evaluation.

Run with /usr/bin/python3 (the ROS Python modules live in the system Python)."""
