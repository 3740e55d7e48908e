"""The finepos controller: positioning loop, grasp hand-off, CLI and service."""
