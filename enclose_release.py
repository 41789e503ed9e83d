"""The enclose release this tree is: its version, written here once (pyproject.toml reads it
from here, so the installed package's metadata says the same).

Every layer may import it; it imports nothing.  Read from code, not from the installed
metadata: importlib.metadata brings zipfile, email, csv, tempfile and more, 2.6 MB of RSS
and ~13 ms of CPU in every follower that journals its inputs (the journal's header names
the release that wrote it; issue 50: <= 40 MB per follower).
"""

VERSION = "0.1.0"
