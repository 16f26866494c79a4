"""Our own iBUG-68 annotation of the real head (Lee Perry-Smith), and range renders of it.

The head ("Infinite, 3D Head Scan" by Lee Perry-Smith / Infinite-Realities, CC BY 3.0) ships
without landmarks. :data:`LANDMARKS_MM` are 68 iBUG points placed by hand, independently of any
detector, in the model frame of ``tests/unit/test_realdata.py`` (the mesh scaled to a 150 mm
head breadth; mm).

How they were made
------------------
A frontal colour render (yaw 0, pitch 0; 1600 x 1600 px, focal length 4.5 times the range
scan's: about 7.4 px per mm at the face) was viewed in zoomed crops with a 10 px grid and each
point read off the visible anatomy:

* brows (18-27): five points along each brow's middle line, the first and last at its ends;
* nose (28-36): 28 on the midline at the height of the inner eye corners, 31 at the tip
  (it lies 0.3 mm from the mesh's most forward point), 29 and 30 evenly between; 32-36 along
  the bottom of the nose (the alae's lower edges, 34 at the columella's base);
* eyes (37-48): the eyes are closed, so the corners are the ends of the closed lid line and the
  upper and lower lid points (38/42, 39/41, 44/48, 45/47) lie on that line at a third and two
  thirds of the way between the corners (the iBUG convention for a closed eye);
* lips (49-68): the corners, the vermilion border (51 and 53 on Cupid's bow, 52 at its dip,
  58 the lower lip's lowest border point); the mouth is closed, so the inner points lie on the
  lip line (upper and lower copies 1 px apart);
* jawline (1-17): iBUG puts it on the face's silhouette. The silhouette was traced on the
  render's own range data as the outline of the face where its surface turns beyond 72 degrees
  from the view ray (over the neck and in front of the ears), from the height of the outer eye
  corners plus 6 mm on one side to the other, and 17 points set at equal arc lengths along it;
  the trace was checked over the image.

Each pixel was back-projected through the render's range data to the surface (model frame).

Estimated uncertainty (1 sigma, across the anatomy's edge): eye corners and lid line, lip
corners and lip line 0.3-0.5 mm; the vermilion border 0.5-1 mm (a soft edge); nose bottom
0.7 mm; brows 1 mm (a 6 mm wide band whose middle is a matter of judgement); along the
jawline 2 mm (equal arc lengths are a convention), across it 0.5 mm. At 640 x 480 (1.6 px per
mm) that is about 0.5-1.5 px inside the face and up to 3 px along the jaw. The jawline of a
turned view is no longer on that view's silhouette: its truth holds only near the front.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The 68 iBUG points of the real head, model frame of tests/unit/test_realdata.py, mm.
LANDMARKS_MM = np.array(
    [
        [-56.16, 60.87, 55.54],
        [-54.77, 48.97, 59.18],
        [-53.93, 34.55, 58.85],
        [-51.57, 20.44, 59.86],
        [-46.80, 9.26, 65.07],
        [-41.31, -3.99, 64.09],
        [-31.09, -13.25, 69.14],
        [-19.03, -17.93, 81.27],
        [-5.39, -19.79, 87.08],
        [8.42, -18.88, 84.89],
        [20.66, -12.94, 75.90],
        [31.34, -5.96, 66.18],
        [38.11, 6.14, 63.24],
        [42.40, 18.21, 57.66],
        [44.08, 32.53, 58.61],
        [45.26, 46.89, 58.01],
        [47.75, 61.12, 52.85],
        [-46.18, 76.81, 71.95],
        [-38.69, 81.66, 81.10],
        [-31.62, 82.89, 83.26],
        [-23.19, 82.86, 85.65],
        [-14.82, 82.00, 87.16],
        [6.85, 81.59, 87.03],
        [15.21, 82.58, 85.95],
        [23.63, 82.33, 83.59],
        [30.79, 80.42, 79.37],
        [38.40, 76.27, 68.07],
        [-3.71, 69.80, 91.81],
        [-3.71, 61.46, 97.21],
        [-3.71, 53.25, 103.35],
        [-3.71, 45.23, 107.26],
        [-12.66, 39.23, 93.57],
        [-8.38, 38.34, 95.29],
        [-3.71, 38.06, 98.18],
        [0.97, 38.31, 94.39],
        [5.24, 39.24, 93.80],
        [-42.34, 67.74, 69.44],
        [-33.62, 66.25, 78.37],
        [-25.34, 67.23, 78.14],
        [-16.94, 70.59, 76.31],
        [-25.34, 67.09, 78.14],
        [-33.68, 66.09, 76.79],
        [8.96, 70.17, 76.32],
        [16.93, 67.51, 78.40],
        [24.94, 66.53, 78.37],
        [33.35, 68.02, 69.62],
        [24.99, 66.38, 77.01],
        [16.93, 67.37, 78.43],
        [-19.97, 15.99, 86.32],
        [-13.90, 21.31, 93.22],
        [-7.96, 24.55, 96.60],
        [-3.57, 24.03, 97.15],
        [0.96, 24.52, 96.16],
        [7.19, 21.25, 92.33],
        [13.82, 16.23, 85.89],
        [7.47, 13.21, 91.78],
        [1.93, 11.74, 94.23],
        [-3.57, 11.19, 94.20],
        [-9.07, 11.75, 94.34],
        [-14.34, 13.20, 91.71],
        [-18.87, 16.10, 85.93],
        [-11.17, 17.45, 91.23],
        [-3.57, 17.96, 92.66],
        [4.31, 17.58, 91.10],
        [12.70, 16.40, 86.26],
        [4.30, 17.45, 91.23],
        [-3.57, 17.83, 92.77],
        [-11.17, 17.32, 91.36],
    ]
)


@dataclass(frozen=True)
class RealTake:
    """A range render of the real head with its colour and the annotation projected.

    Attributes
    ----------
    name : str
    color : (480, 640, 3) uint8
    xyz : (480, 640, 3) float64, camera frame, mm (NaN = no surface)
    truth : (68, 2) float64, px
    """

    name: str
    color: np.ndarray
    xyz: np.ndarray
    truth: np.ndarray


def load_real_head():
    """The head of tests/unit/test_realdata.py (read from tests/support/real_head.py's folder)."""
    from tests.unit import test_realdata as rd

    return rd.load_head()


def real_takes(head, poses, zoom: float = 1.0) -> list[RealTake]:
    """Colour range renders of the head (640 x 480, lit from the camera) and their truth.

    Parameters
    ----------
    head
        From :func:`load_real_head`.
    poses : list of (yaw, pitch) degrees
    zoom : float
        Times the realdata range scan's focal length (1: about 1.6 px per mm at the face).

    Returns
    -------
    list of RealTake
    """
    from tests.unit import test_realdata as rd

    out = []
    for yaw, pitch in poses:
        xyz, colour, K, R, centre = rd._colour_scan(head, yaw, pitch, 1.0, zoom)
        world = LANDMARKS_MM @ head.R_w.T + head.t_w
        truth = rd._project(world, K, R, centre)
        out.append(RealTake(f"yaw {yaw:+g} pitch {pitch:+g}", colour, xyz, truth))
    return out


def detected_real_takes(poses) -> list[tuple[RealTake, np.ndarray]]:
    """The real head's colour renders in ``poses`` (:func:`real_takes`), each with the
    detector's points on it (68, 2) px: what a doubtful detection's feature steps start from."""
    from scan2morph.landmarks import detect

    return [
        (take, detect(take.color, take.xyz, take.name).points)
        for take in real_takes(load_real_head(), poses)
    ]
