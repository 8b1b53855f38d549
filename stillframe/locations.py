"""Where stillframe's files are: the package's data and the checkout's scenes."""

from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
#: files installed with the package: the bundled identified model, the fidelity table, service
#: definitions and the dashboard page
DATA_DIR = PACKAGE_DIR / "data"
#: the checkout the package runs from (editable install): scenes/, bags/ and the node packages
REPO_ROOT = PACKAGE_DIR.parent
SCENES_DIR = REPO_ROOT / "scenes"
#: real measured records shipped with their licences (DaISy 96-013)
DATASETS_DIR = REPO_ROOT / "datasets"


def shipped_scenes() -> list[str]:
    """The names of the scenes shipped in :data:`SCENES_DIR` (``thesis_lqg``, ...), sorted."""
    return sorted(p.stem for p in SCENES_DIR.glob("*.yaml"))


def find_scene(text: str) -> Path | None:
    """The scene file SCENE names: an existing path as given, else a shipped scene by its name
    (``thesis_lqg`` or ``thesis_lqg.yaml`` is ``scenes/thesis_lqg.yaml``); None if neither."""
    path = Path(text)
    if path.is_file():
        return path
    if path.name == text:  # a bare name, not a path into some directory
        shipped = SCENES_DIR / (text if path.suffix in (".yaml", ".yml") else f"{text}.yaml")
        if shipped.is_file():
            return shipped
    return None
