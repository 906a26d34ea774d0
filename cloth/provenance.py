"""Which code made a result: the git commit a measurement page or a tour page names."""
import os
import subprocess


def commit():
    """The git commit of the code that runs (LOOM_COMMIT overrides it, for runs from an
    exported copy of a commit), marked when cloth/ or scenes/ differ from it."""
    if os.environ.get("LOOM_COMMIT"):
        return os.environ["LOOM_COMMIT"]
    try:
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        out = subprocess.run(["git", "-C", root, "rev-parse", "--short", "HEAD"],
                             capture_output=True, text=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", root, "status", "--porcelain", "cloth", "scenes"],
                               capture_output=True, text=True).stdout.strip()
        return (out + (" (cloth/ or scenes/ modified)" if dirty else "")) or "unknown"
    except OSError:
        return "unknown"
