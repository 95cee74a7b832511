"""Memory and time known before they are spent (design §16): what the machine has, what a job needs.

Every command that allocates by a user's number (team size, ``--nconmax``/``--njmax``/``--worlds``,
sweep size, calibration budget) estimates its memory with the models here and refuses with exit 2
and the estimate (:func:`require`) when it does not fit in :func:`available_memory`.
"""

from __future__ import annotations

import os

from bioform_mj.core.errors import InputError

#: share of the available memory one job may plan to use
SHARE = 0.9

#: MuJoCo scene of n robots (the compiled model's ``nbuffer`` + ``MjData``'s ``nbuffer`` and arena), bytes:
#: a + b n + c n², least-squares fit (within 0.1 %) to the paper robot's scenes measured with MuJoCo 4.0.0
#: at n = 3, 16, 64, 256 (23.8, 26.4, 58.0, 300.8 MB); the n² term is the arena MuJoCo sizes for contacts.
SCENE_BYTES = (18.4e6, 457e3, 2523.0)


def fmt_bytes(b: float) -> str:
    """``b`` bytes as ``1.23 GB`` (decimal units)."""
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if b >= size:
            return f"{b / size:.3g} {unit}"
    return f"{b / 1e3:.3g} kB"


def fmt_seconds(s: float) -> str:
    """A duration as ``45 s``, ``12 min``, ``3.4 h`` or ``5.1 days``."""
    if s < 90:
        return f"{s:.0f} s"
    if s < 5400:
        return f"{s / 60:.0f} min"
    if s < 172800:
        return f"{s / 3600:.1f} h"
    return f"{s / 86400:.3g} days"


def _cgroup_free() -> int | None:
    """Bytes left under this process's cgroup v2 memory limit (None: no limit or not readable)."""
    try:
        rel = ""
        with open("/proc/self/cgroup") as fh:
            for line in fh:
                if line.startswith("0::"):
                    rel = line[3:].strip()
        base = "/sys/fs/cgroup" + (rel if rel != "/" else "")
        for d in (base, "/sys/fs/cgroup"):
            try:
                with open(os.path.join(d, "memory.max")) as fh:
                    lim = fh.read().strip()
            except OSError:
                continue
            if lim == "max":
                return None
            with open(os.path.join(d, "memory.current")) as fh:
                cur = int(fh.read().strip())
            return max(0, int(lim) - cur)
    except (OSError, ValueError):
        return None
    return None


def available_memory() -> int:
    """Bytes this process can still allocate: ``MemAvailable`` of /proc/meminfo (psutil or sysconf off
    Linux), or less: the cgroup's limit less its usage, the address space left under ``ulimit -v``."""
    avail = None
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except OSError:
        pass
    if avail is None:
        try:
            import psutil

            avail = int(psutil.virtual_memory().available)
        except ImportError:
            avail = int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    cg = _cgroup_free()
    if cg is not None:
        avail = min(avail, cg)
    room = _address_space_left()
    return min(avail, room) if room is not None else avail


def _address_space_left() -> int | None:
    """Bytes of address space left under ``ulimit -v`` (RLIMIT_AS) for this process (None: unlimited)."""
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft == resource.RLIM_INFINITY or soft < 0:
            return None
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmSize:"):
                    return max(0, soft - int(line.split()[1]) * 1024)
    except (ImportError, OSError, ValueError):
        return None
    return None


def scene_bytes(n_robots: int) -> float:
    """Estimated bytes of a compiled MuJoCo scene of ``n_robots`` robots and its data (:data:`SCENE_BYTES`)."""
    a, b, c = SCENE_BYTES
    return a + b * n_robots + c * float(n_robots) ** 2


def require(need: float, what: str, hint: str = "", free: float | None = None, where: str = "memory") -> None:
    """InputError (exit 2) when ``need`` bytes exceed :data:`SHARE` of ``free`` (default: the machine's
    available memory), naming ``what`` and the estimate."""
    free = available_memory() if free is None else free
    if need > SHARE * free:
        raise InputError(
            f"{what} needs about {fmt_bytes(need)} of {where} (estimated), {fmt_bytes(free)} available"
            + (f"; {hint}" if hint else "")
        )
