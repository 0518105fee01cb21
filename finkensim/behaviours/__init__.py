"""Swarm controllers: functions from a copter's own state/sensor readings to velocity commands."""
