"""Write specs/robots/servicer_panda.urdf: the Franka Panda of the example-robot-data
collection (a maintained robot description) mounted on the servicer's bus.

    .venv/bin/python scripts/make_servicer_panda.py   # needs the dev extra (example-robot-data)

Kept from the collection's ``panda_description/urdf/panda.urdf``: every link's inertial, every
joint (origin, axis, limits), the hand and its two finger joints. Dropped: visual and
collision geometry (meshes are not shipped; no inertia comes from them), the safety
controller and the joint dynamics (friction and damping; the simulator models neither).
Added: the servicer's bus link and its mount (specs/robots/servicer_ur3.urdf [S1], [S2],
[S7]) and a massless camera link at the hand's TCP frame, boresight along the hand's z-axis.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from importlib import metadata
from pathlib import Path

SOURCE = "cmeel.prefix/share/example-robot-data/robots/panda_description/urdf/panda.urdf"
OUT = Path(__file__).resolve().parent.parent / "specs" / "robots" / "servicer_panda.urdf"
DROP = ("visual", "collision", "safety_controller", "dynamics")

HEADER = """<?xml version="1.0"?>
<!--
  Free-floating inspection servicer with a redundant 7-DoF arm: the Franka Emika Panda of the
  example-robot-data collection on the servicer's bus, with an inspection camera at the hand.
  No meshes: inertial data only. The free-flyer root joint is added by the loader. Written by
  scripts/make_servicer_panda.py from the collection's file; edit that script, not this file.

  Sources of the numbers
  [P1] Arm and hand: example-robot-data {version} (BSD-3-Clause),
       panda_description/urdf/panda.urdf (generated from franka_ros' panda.urdf.xacro): every
       link's mass, centre of mass and inertia, every joint's origin, axis and limits, as
       published there. The two finger joints (prismatic) stay; a spec locks them
       (robot.locked_joints).
  [S1] Bus mass and envelope: as specs/robots/servicer_ur3.urdf [S1], an ESPA-class small
       satellite, 150 kg in a 0.6 x 0.7 x 0.9 m box.
  [S2] Bus inertia: uniform-density cuboid of [S1] (servicer_ur3.urdf [S2]).
  [S7] Arm mount: the arm base (panda_link0) at the centre of the bus +z face, 0.45 m above the
       bus origin (servicer_ur3.urdf [S7]).
  [C1] Camera frame: the hand's TCP frame of [P1] (panda_hand_tcp, 0.1034 m along the hand's
       z-axis), boresight = +z; massless (the camera's mass is not modelled on this arm).
-->
"""

BUS = """  <link name="bus">
    <inertial>
      <origin xyz="0 0 0" rpy="0 0 0"/>
      <mass value="150.0"/>                                  <!-- [S1] -->
      <inertia ixx="16.25" ixy="0" ixz="0" iyy="14.625" iyz="0" izz="10.625"/>  <!-- [S2] -->
    </inertial>
  </link>
  <joint name="bus_mount" type="fixed">
    <parent link="bus"/>
    <child link="panda_link0"/>
    <origin xyz="0 0 0.45" rpy="0 0 0"/>                   <!-- [S7] -->
  </joint>
"""

CAMERA = """  <joint name="camera_joint" type="fixed">
    <parent link="panda_hand_tcp"/>
    <child link="camera"/>
    <origin xyz="0 0 0" rpy="0 0 0"/>                       <!-- [C1] -->
  </joint>
  <link name="camera"/>
"""


def main() -> None:
    dist = metadata.distribution("example-robot-data")
    root = ET.parse(Path(dist.locate_file(SOURCE))).getroot()
    body = []
    for element in root:
        if element.tag not in ("link", "joint"):
            continue
        for parent in element.iter():
            for child in [c for c in parent if c.tag in DROP]:
                parent.remove(child)
        ET.indent(element, space="  ", level=1)
        body.append("  " + ET.tostring(element, encoding="unicode").strip() + "\n")
    text = (HEADER.format(version=dist.version) + '<robot name="servicer_panda">\n' + BUS
            + "".join(body) + CAMERA + "</robot>\n")
    tmp = OUT.with_suffix(".tmp")
    tmp.write_text(text)
    tmp.replace(OUT)
    print(f"-> {OUT}")


if __name__ == "__main__":
    main()
