"""The episode runner: ``aw-run`` drives baseline agents or agent harnesses through ``aw-serve``."""
