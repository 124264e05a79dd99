"""Child process for the kill test: record a simulated rig forever (until killed).

Usage: python rigrec_kill_child.py SOURCE_SESSION OUT_SESSION
"""

import sys
from pathlib import Path

from rigkit import rig_dict

from rigs import Recorder, Rig, SessionWriter


def main() -> None:
    source, out = Path(sys.argv[1]), Path(sys.argv[2])
    with Rig.open(rig_dict(source), epoch_ns=0) as rig:
        writer = SessionWriter.create(out, rig.camera_names, rig=rig.name, fps=60.0,
                                      calibration=rig.calibration_path, compression=0)  # fmt: skip
        with Recorder(writer, queue_size=4) as rec:
            for mf in rig.multiframes(None):
                rec.submit(mf)


if __name__ == "__main__":
    main()
