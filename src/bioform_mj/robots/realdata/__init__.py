"""Real robots (issue 29): a recording read (:mod:`.recording`), the robot's parameters fitted to it with
``mujoco.sysid`` (:mod:`.fit`), replayed open loop (:mod:`.replay`), and the drive program to record
(:mod:`.program`). The command line is :mod:`bioform_mj.cli.realdata`
(``bioform robot fit / replay / drive-program``); the calibrated robot file is :mod:`.calibrated`."""
