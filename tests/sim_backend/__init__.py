"""Tests of the simulated work cell (sim_backend)."""
