"""Assessments of a robot and of a run: the robot check, identification and its causes, outcomes, the pre-run check
and the hardware verdict (design §13, §14, §19).
"""
