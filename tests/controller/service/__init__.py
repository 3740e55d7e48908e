"""Tests of the controller service: protocol, security, faults, systemd, the process."""
