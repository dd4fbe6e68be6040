"""A car body against the track's limits: walls that stop it, edges the wheels run beyond.

Shared by every plant that drives on a racing_lib :class:`~racing_lib.geometry.Track`
(:class:`racing_lib.sim.SimulatedCar` and the plants of :mod:`racing_lib.plants`), so that a wall
stops a car, and is counted, the same way whichever equations move the car between two checks:

* :class:`TrackTables`: the centerline's heading, the widths and the grade on a ~1 m grid, looked
  up by arc length (scalar lookups on the hot path);
* :class:`WallContact`: keeps the body's corners inside the walls (a plastic impact at the deepest
  corner, with wall friction) and counts contact episodes and their duration;
* :func:`wheels_beyond_edge`: which wheels are beyond an open track's edge.

A plant calls them after each integration substep with its position in Frenet coordinates.
"""

from __future__ import annotations

import math

import numpy as np

from racing_lib.geometry import Track

__all__ = ["TrackTables", "WallContact", "wheels_beyond_edge"]


class TrackTables:
    """Heading, widths and grade of a track on a ~1 m grid, as Python lists for scalar lookups.

    Parameters
    ----------
    track : Track
        The track; its centerline gives the heading (rad), its widths the edges (m), its
        elevation the grade (rad).
    """

    def __init__(self, track: Track) -> None:
        length = track.length
        n = max(16, math.ceil(length / 1.0))
        ds = length / n
        s = np.arange(n + 1) * ds
        s[-1] = 0.0  # closure: the last entry repeats s = 0
        heading = np.unwrap(np.asarray(track.centerline.heading(s), dtype=float))
        self._ds = ds
        self._n_tab = n
        self._length = length
        self._tab_heading = heading.tolist()
        self._tab_wl = np.asarray(track.width_left(s), dtype=float).tolist()
        self._tab_wr = np.asarray(track.width_right(s), dtype=float).tolist()
        self._tab_grade = np.asarray(track.grade(s), dtype=float).tolist()

    def lookup(self, s: float) -> tuple[float, float, float, float]:
        """(heading, rad; width_left, m; width_right, m; grade, rad) at arc length s (m).

        Linear interpolation on the grid; s is taken modulo the track's length.
        """
        u = (s % self._length) / self._ds
        i = int(u)
        if i >= self._n_tab:
            i = self._n_tab - 1
        w = u - i
        h, wl, wr, gr = self._tab_heading, self._tab_wl, self._tab_wr, self._tab_grade
        return (
            h[i] + w * (h[i + 1] - h[i]),
            wl[i] + w * (wl[i + 1] - wl[i]),
            wr[i] + w * (wr[i + 1] - wr[i]),
            gr[i] + w * (gr[i + 1] - gr[i]),
        )


def wheels_beyond_edge(
    e_y: float,
    sp: float,
    cp: float,
    wl: float,
    wr: float,
    wheels_xy: tuple[tuple[float, float], ...],
) -> list[bool]:
    """For each wheel, whether it is beyond the track's edge.

    Parameters
    ----------
    e_y : float
        Lateral offset of the centre of gravity from the centerline, m (left positive).
    sp, cp : float
        Sine and cosine of the heading relative to the centerline, -.
    wl, wr : float
        Track widths left and right of the centerline, m.
    wheels_xy : tuple of (x, y)
        Wheel positions in the body frame relative to the centre of gravity, m.
    """
    out = []
    for lx, ly in wheels_xy:
        e_w = e_y + lx * sp + ly * cp
        out.append(e_w > wl or e_w < -wr)
    return out


class WallContact:
    """Walls keep the body's corners on the track; each contact is a plastic impact, counted.

    Parameters
    ----------
    m : float
        Mass, kg.
    I_zz : float
        Yaw moment of inertia, kg m^2.
    front, rear : float
        Body front ahead of the centre of gravity (> 0) and body rear (< 0, behind it), m.
    width : float
        Body width, m.
    wall_mu : float
        Friction coefficient between body and wall, -.
    wall_entry_keep : float
        Share of the speed kept when a contact episode begins, -.
    wall_release_gap : float
        An episode ends only once the body is this far from the wall, m.

    Attributes
    ----------
    contacts : int
        Contact episodes since :meth:`reset` (a car scraping along a wall counts once).
    contact_time : float
        Time spent touching a wall since :meth:`reset`, s.
    touching : bool
        The body touched a wall at the last check.
    """

    def __init__(
        self,
        m: float,
        I_zz: float,
        front: float,
        rear: float,
        width: float,
        wall_mu: float,
        wall_entry_keep: float,
        wall_release_gap: float,
    ) -> None:
        self.m, self.I_zz = m, I_zz
        self.front, self.rear, self.width = front, rear, width
        self.wall_mu, self.wall_entry_keep = wall_mu, wall_entry_keep
        self.wall_release_gap = wall_release_gap
        self.reset()

    def reset(self) -> None:
        """Zero the counters and leave any contact episode."""
        self.contacts = 0
        self.contact_time = 0.0
        self.in_contact = False  # inside a contact episode (with release hysteresis)
        self.touching = False

    def check(
        self,
        st: list[float],
        h: float,
        e_y: float,
        heading: float,
        wl: float,
        wr: float,
        sp: float,
        cp: float,
    ) -> float:
        """Keep the body's corners inside the walls after a substep of length h; the new e_y.

        The deepest corner is pushed back onto the wall, and an impulse at that corner removes its
        velocity into the wall (no bounce). The impulse acts at the corner, so it also turns the
        car (a nose-first hit swings the car parallel to the wall), and wall friction takes
        tangential speed in proportion to it; the first impact of an episode costs a further share
        of the speed (``wall_entry_keep``).

        Parameters
        ----------
        st : list of float
            The car's state, starting ``[x (m), y (m), psi (rad), vx (m/s), vy (m/s), r
            (rad/s)]`` (body-frame velocities); changed in place on a contact.
        h : float
            Length of the substep just taken, s (added to ``contact_time`` on a contact).
        e_y : float
            Lateral offset of the centre of gravity from the centerline, m.
        heading : float
            Centerline heading at the car, rad.
        wl, wr : float
            Distances from the centerline to the left and right walls, m.
        sp, cp : float
            Sine and cosine of the heading relative to the centerline, -.

        Returns
        -------
        float
            e_y after the push back onto the wall, m.
        """
        # Lateral extent of the body corners relative to the centerline (local straight
        # approximation of the edge, good to millimetres at these corner sizes).
        front, rear, half_w = self.front, self.rear, 0.5 * self.width
        half_wc = half_w * abs(cp)
        pen_left = e_y + max(front * sp, rear * sp) + half_wc - wl
        pen_right = -wr - (e_y + min(front * sp, rear * sp) - half_wc)
        if pen_left <= 0.0 and pen_right <= 0.0:
            self.touching = False
            if self.in_contact and min(-pen_left, -pen_right) > self.wall_release_gap:
                self.in_contact = False
            return e_y
        # into = +1: the left wall (along the path normal n, which points left); -1: the right one.
        if pen_left >= pen_right:
            depth, into = pen_left, 1.0
        else:
            depth, into = pen_right, -1.0
        # The deepest corner in body coordinates.
        lx = front if into * sp > 0.0 else rear
        ly = into * half_w if cp > 0.0 else -into * half_w
        nx, ny = -math.sin(heading), math.cos(heading)
        st[0] -= into * depth * nx
        st[1] -= into * depth * ny
        e_y = e_y - into * depth
        entering = not self.in_contact

        psi, r = st[2], st[5]
        c, s = math.cos(psi), math.sin(psi)
        vx, vy = st[3], st[4]
        vwx, vwy = vx * c - vy * s, vx * s + vy * c  # CoG velocity, world frame
        cx, cy = lx * c - ly * s, lx * s + ly * c  # corner relative to the CoG, world frame
        ncx, ncy = -into * nx, -into * ny  # contact normal, from the wall into the track
        tcx, tcy = -ncy, ncx  # contact tangent
        vcx, vcy = vwx - r * cy, vwy + r * cx  # corner velocity
        v_n = vcx * ncx + vcy * ncy  # < 0: the corner moves into the wall
        if v_n < 0.0:
            inv_m, inv_i = 1.0 / self.m, 1.0 / self.I_zz
            arm_n = cx * ncy - cy * ncx  # (corner x normal)_z
            arm_t = cx * tcy - cy * tcx
            j_n = -v_n / (inv_m + arm_n * arm_n * inv_i)  # plastic: corner's normal speed -> 0
            v_t = vcx * tcx + vcy * tcy
            j_t_stop = abs(v_t) / (inv_m + arm_t * arm_t * inv_i)
            j_t = -math.copysign(min(self.wall_mu * j_n, j_t_stop), v_t)  # Coulomb wall friction
            vwx += (j_n * ncx + j_t * tcx) * inv_m
            vwy += (j_n * ncy + j_t * tcy) * inv_m
            r += (j_n * arm_n + j_t * arm_t) * inv_i
        if entering:
            # Impact losses beyond friction (crushing, scrubbing): keep a share of the speed.
            vwx *= self.wall_entry_keep
            vwy *= self.wall_entry_keep
            self.contacts += 1
            self.in_contact = True
        st[3] = vwx * c + vwy * s
        st[4] = -vwx * s + vwy * c
        st[5] = r
        self.touching = True
        self.contact_time += h
        return e_y
