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
