"""Make tests/naive.py (the plain-numpy reference kernel) importable as ``naive``."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
