"""The per-frame loops of perception, compiled (numba), each one pass over its data.

The saturation image, the object mask with its column and row counts and moments, and the
coverage-weighted centre were a dozen OpenCV and numpy calls each; at a few microseconds of
call overhead apiece on a 192x144 frame that was most of the perception time. The networks'
forward pass is one call instead of four numpy ones (each look runs four networks). Every kernel
gives what those calls gave (tests/calibration_free/test_kernels.py holds them against the
OpenCV formulas).

The kernels are compiled when this module is first imported and cached on disk (numba's
cache: beside this file, else under ``NUMBA_CACHE_DIR`` or the user's cache folder); a cached
import takes a fraction of a second, a first one a few seconds.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from calibration_free.preprocess import SATURATION_FLOOR


@njit("float32[:, ::1](uint8[:, :, ::1])", cache=True, nogil=True, error_model="numpy")
def saturation_image(image: np.ndarray) -> np.ndarray:  # pragma: no cover
    """(max - min) / max(max, floor) * 255 of an HxWx3 uint8 image, as HxW float32: the grey
    levels of ``preprocess.max_and_saturation_u8`` (OpenCV's division rounds the float32
    quotient half to even, as ``np.rint`` does)."""
    height, width = image.shape[0], image.shape[1]
    flat = image.reshape(height * width * 3)
    out = np.empty(height * width, np.float32)
    floor = np.uint8(SATURATION_FLOOR)
    for k in range(height * width):
        r, g, b = flat[3 * k], flat[3 * k + 1], flat[3 * k + 2]
        top = max(r, g, b)
        out[k] = np.rint(np.float32(top - min(r, g, b)) * np.float32(255.0)
                         / np.float32(max(top, floor)))
    return out.reshape(height, width)


@njit("Tuple((uint8[:, ::1], float64[::1], int64[::1]))(float32[:, ::1], float32, boolean)",
      cache=True, nogil=True, error_model="numpy")
def object_mask(image: np.ndarray, threshold: np.float32, bright: bool):  # pragma: no cover
    """The object mask (255 where the pixel is beyond the threshold: above it for a bright
    part, at or below it for a dark one), its moments (count, sums of u, v, u*u, v*v, u*v;
    pixel-centre coordinates) and its box (first column, width, first row, height; width and
    height 0 unless the occupied columns, and the occupied rows, are one run each)."""
    height, width = image.shape
    mask = np.empty((height, width), np.uint8)
    cols = np.zeros(width, np.int64)
    n = 0
    s_u = s_v = s_uu = s_vv = s_uv = 0.0
    row_first = row_last = -1
    rows_used = 0
    for i in range(height):
        count = 0
        row_u = 0
        row_uu = 0
        for j in range(width):
            inside = np.int64((image[i, j] > threshold) == bright)
            mask[i, j] = np.uint8(255 * inside)
            cols[j] += inside
            count += inside
            row_u += inside * j
            row_uu += inside * j * j
        if count:
            n += count
            s_u += row_u
            s_uu += row_uu
            s_v += i * count
            s_vv += i * i * count
            s_uv += i * row_u
            rows_used += 1
            if row_first < 0:
                row_first = i
            row_last = i
    col_first = col_last = -1
    cols_used = 0
    for j in range(width):
        if cols[j]:
            cols_used += 1
            if col_first < 0:
                col_first = j
            col_last = j
    moments = np.empty(6, np.float64)
    moments[0], moments[1], moments[2] = n, s_u, s_v
    moments[3], moments[4], moments[5] = s_uu, s_vv, s_uv
    box = np.zeros(4, np.int64)
    if n and cols_used == col_last - col_first + 1 and rows_used == row_last - row_first + 1:
        box[0], box[1] = col_first, cols_used
        box[2], box[3] = row_first, rows_used
    return mask, moments, box


@njit("uint8[:, ::1](uint8[:, :])", cache=True, nogil=True, error_model="numpy")
def filled_blob(blob: np.ndarray) -> np.ndarray:  # pragma: no cover
    """A copy of ``blob`` (nonzero: the part) that is 255 on the part and on its holes (the
    background pixels not 4-connected to the window's border) and 0 elsewhere.

    A background pixel with no part pixel on one side of it along its row or its column
    reaches the border along that line: only the others (inside the blob's row and column
    spans) can lie in a hole, and a 4-connected set of them is a hole unless it touches one
    that can reach the border."""
    height, width = blob.shape
    out = np.zeros((height, width), np.uint8)
    row_lo = np.full(height, width, np.int64)
    row_hi = np.full(height, -1, np.int64)
    col_lo = np.full(width, height, np.int64)
    col_hi = np.full(width, -1, np.int64)
    for i in range(height):
        for j in range(width):
            if blob[i, j]:
                out[i, j] = 255
                row_lo[i] = min(row_lo[i], j)
                row_hi[i] = max(row_hi[i], j)
                col_lo[j] = min(col_lo[j], i)
                col_hi[j] = max(col_hi[j], i)
    seen = np.zeros((height, width), np.uint8)
    stack = np.empty(height * width, np.int64)
    component = np.empty(height * width, np.int64)
    for i0 in range(1, height - 1):
        for j0 in range(row_lo[i0] + 1, row_hi[i0]):
            if out[i0, j0] or seen[i0, j0] or not col_lo[j0] < i0 < col_hi[j0]:
                continue
            seen[i0, j0] = 1
            stack[0] = i0 * width + j0
            top, size, hole = 1, 0, True
            while top:
                top -= 1
                k = stack[top]
                component[size] = k
                size += 1
                i, j = k // width, k % width
                if not (row_lo[i] < j < row_hi[i] and col_lo[j] < i < col_hi[j]):
                    hole = False  # this one reaches the border along its row or column
                    continue
                for y, x in ((i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1)):
                    if out[y, x]:
                        continue
                    if seen[y, x] == 2:  # found outside by an earlier search
                        hole = False
                    elif not seen[y, x]:
                        seen[y, x] = 1
                        stack[top] = y * width + x
                        top += 1
            for n in range(size):
                y, x = component[n] // width, component[n] % width
                if hole:
                    out[y, x] = 255
                else:
                    seen[y, x] = 2
    return out


@njit("Tuple((float64, float64, float64))"
      "(float32[:, :], uint8[:, :], uint8[:, :], uint8[:, :], boolean)", cache=True, nogil=True,
      error_model="numpy")
def coverage_moments(window: np.ndarray, core: np.ndarray, band: np.ndarray,
                     ring: np.ndarray, bright: bool):  # pragma: no cover
    """Moments (weight, sum of u * weight, sum of v * weight; window coordinates) of the
    part's coverage: 1 in ``core`` (which lies in ``band``), in the rest of ``band`` the way
    from the ring's mean level (the background) to the core's (the part), within 0..1, 0
    elsewhere. All zero when core
    or ring is empty or the part is not beyond the background (brighter for a bright part,
    darker for a dark one)."""
    height, width = window.shape
    n_in = n_out = 0
    s_in = s_out = 0.0
    for i in range(height):
        for j in range(width):
            if core[i, j]:
                n_in += 1
                s_in += window[i, j]
            elif ring[i, j]:
                n_out += 1
                s_out += window[i, j]
    if n_in == 0 or n_out == 0:
        return 0.0, 0.0, 0.0
    inside, outside = s_in / n_in, s_out / n_out
    if not ((inside > outside) if bright else (inside < outside)):
        return 0.0, 0.0, 0.0
    scale = 1.0 / (inside - outside)
    m00 = m10 = m01 = 0.0
    for i in range(height):
        for j in range(width):
            if band[i, j]:  # the core lies in the band
                w = 1.0 if core[i, j] else min(max((window[i, j] - outside) * scale, 0.0),
                                               1.0)
                m00 += w
                m10 += w * j
                m01 += w * i
    return m00, m10, m01


@njit("UniTuple(int64, 2)(float64[:, :, ::1], uint8[:, :], uint8[:, :], int64, int64, int64, "
      "int64, float64[::1], float64[::1])", cache=True, nogil=True, error_model="numpy")
def _colour_sums(lin: np.ndarray, core: np.ndarray, ring: np.ndarray, i0: int, i1: int,
                 j0: int, j1: int, fg: np.ndarray, bg: np.ndarray):  # pragma: no cover
    """Adds to ``fg`` the colours of the ``core`` pixels and to ``bg`` those of the ``ring``
    pixels in rows i0..i1 - 1 and columns j0..j1 - 1 of ``lin`` (H x W x 3); returns how many
    of each."""
    n_core = n_ring = 0
    for y in range(i0, i1):
        for x in range(j0, j1):
            if core[y, x]:
                n_core += 1
                for k in range(3):
                    fg[k] += lin[y, x, k]
            elif ring[y, x]:
                n_ring += 1
                for k in range(3):
                    bg[k] += lin[y, x, k]
    return n_core, n_ring


@njit("float64[:, :, ::1](uint8[:, :, :], float64[::1])", cache=True, nogil=True,
      error_model="numpy", inline="always")
def _linear_image(rgb: np.ndarray, linear: np.ndarray) -> np.ndarray:  # pragma: no cover
    """Each pixel's colour in linear light (``linear`` maps grey levels to it), H x W x 3."""
    height, width = rgb.shape[0], rgb.shape[1]
    lin = np.empty((height, width, 3))
    for i in range(height):
        for j in range(width):
            for k in range(3):
                lin[i, j, k] = linear[rgb[i, j, k]]
    return lin


@njit("boolean(float64[:, :, ::1], uint8[:, :], uint8[:, :], float64, float64[::1], "
      "float64[::1])", cache=True, nogil=True, error_model="numpy", inline="always")
def _window_colours(lin: np.ndarray, core: np.ndarray, ring: np.ndarray, min_contrast: float,
                    fg0: np.ndarray, bg0: np.ndarray) -> bool:  # pragma: no cover
    """Into ``fg0`` (zeros) the mean colour of the window's ``core`` pixels, into ``bg0``
    (zeros) that of its ``ring`` pixels. False where the coverage cannot be read: no pixel of
    either, a black part, or a background with less than ``min_contrast`` across the part's
    colour direction."""
    height, width = core.shape
    n_in, n_out = _colour_sums(lin, core, ring, 0, height, 0, width, fg0, bg0)
    if n_in == 0 or n_out == 0:
        return False
    fg0 /= n_in
    bg0 /= n_out
    norm0 = np.sqrt(fg0[0] * fg0[0] + fg0[1] * fg0[1] + fg0[2] * fg0[2])
    if norm0 <= 0.0:
        return False
    cb0 = bb0 = 0.0
    for k in range(3):
        cb0 += fg0[k] / norm0 * bg0[k]
        bb0 += bg0[k] * bg0[k]
    return bb0 - cb0 * cb0 >= min_contrast * min_contrast


@njit("float64(float64[:, :, ::1], uint8[:, :], uint8[:, :], int64, int64, float64[::1], "
      "float64[::1], float64[::1], float64[::1])", cache=True, nogil=True, error_model="numpy",
      inline="always")
def _square_colours(lin: np.ndarray, core: np.ndarray, ring: np.ndarray, i: int, j: int,
                    fg0: np.ndarray, bg0: np.ndarray, fg: np.ndarray,
                    bg: np.ndarray) -> float:  # pragma: no cover
    """Into ``fg`` the mean colour of the ``core`` pixels in the 5x5 square around pixel
    (i, j), into ``bg`` that of its ``ring`` pixels (the window's, ``fg0`` and ``bg0``,
    where the square has none); returns the length of ``fg``."""
    height, width = core.shape
    fg[:] = 0.0
    bg[:] = 0.0
    nf, nb = _colour_sums(lin, core, ring, max(i - 2, 0), min(i + 3, height),
                          max(j - 2, 0), min(j + 3, width), fg, bg)
    if nf:
        fg /= nf
    else:
        fg[:] = fg0
    if nb:
        bg /= nb
    else:
        bg[:] = bg0
    return np.sqrt(fg[0] * fg[0] + fg[1] * fg[1] + fg[2] * fg[2])


@njit("float64(float64[::1], uint8, float64[::1], float64[::1], float64, float64)",
      cache=True, nogil=True, error_model="numpy", inline="always")
def _coverage_share(p: np.ndarray, on_blob: bool, fg: np.ndarray, bg: np.ndarray, norm: float,
                    local_contrast: float) -> float:  # pragma: no cover
    """The part's coverage of a band pixel of linear colour ``p``, from the part's colour
    ``fg`` (of length ``norm``, > 0) and the background's ``bg`` around it, as
    ``colour_coverage_moments`` describes it; ``on_blob``: the pixel is on the blob."""
    cb = pc = pb = bb = 0.0
    for k in range(3):
        c = fg[k] / norm
        cb += c * bg[k]
        pc += p[k] * c
        pb += p[k] * bg[k]
        bb += bg[k] * bg[k]
    across = bb - cb * cb
    if not across >= local_contrast * local_contrast:
        # the table around is too dark for its colour to be told from the part's (the
        # part's own cast shadow): what light the pixel has is the part's, so its share is
        # the part's own
        w = pc / norm
    else:
        beta = (pb - cb * pc) / across
        w = 1.0 - beta
        if not on_blob:
            # mostly table: a shadow's edge along the part's darkens the table here below
            # what the ring shows, which the table's share alone reads as part
            w = 0.5 * (w + (pc - beta * cb) / norm)
    # far beyond 0..1 is no mix of the two colours (a glint, a speck): bounded so that one
    # such pixel cannot move the centre; within, the noise stays unbiased
    return min(max(w, -1.0), 2.0)


@njit("UniTuple(float64, 3)(uint8[:, :, :], uint8[:, :], uint8[:, :], uint8[:, :], "
      "uint8[:, :], float64[::1], float64, float64, float32[:, ::1])", cache=True, nogil=True,
      error_model="numpy")
def colour_coverage_moments(rgb: np.ndarray, blob: np.ndarray, core: np.ndarray,
                            band: np.ndarray, ring: np.ndarray, linear: np.ndarray,
                            min_contrast: float, local_contrast: float,
                            weights: np.ndarray):  # pragma: no cover
    """Moments (weight, sum of u * weight, sum of v * weight; window coordinates) of the
    part's coverage read from each pixel's colour (``localise.colour_centre``): 1 in ``core``;
    in the rest of ``band``, with the pixel's linear colour p = alpha * c + beta * b (c the
    unit direction of the part's colour f, the mean of the ``core`` pixels in the 5x5 square
    around it; b the background's colour, the mean of the ``ring`` pixels there; without
    one there, of all of them), 1 - beta on the ``blob`` (the table's share) and beyond it
    the mean of 1 - beta and alpha / |f| (the part's share); 0 elsewhere. ``linear`` maps
    grey levels to linear light. The weight is not cut to 0..1 (the camera's noise around the
    part's edge would then only add to it, most where the background is dark, and move the
    centre that way), only kept within -1..2. Where the background's mean colour has less
    than ``min_contrast`` across the part's direction (a part of the table's colour) nothing
    is read: all zero. Where only the background around one pixel has less than
    ``local_contrast`` (a black cast shadow: its colour cannot be told from the part's) that
    pixel reads the part's share alone: the light it has is the part's. ``weights`` (the
    window's size) receives each pixel's weight (0 off the band; undefined where all zero is
    returned)."""
    height, width = core.shape
    lin = _linear_image(rgb, linear)
    fg0 = np.zeros(3)
    bg0 = np.zeros(3)
    if not _window_colours(lin, core, ring, min_contrast, fg0, bg0):
        return 0.0, 0.0, 0.0
    fg = np.empty(3)
    bg = np.empty(3)
    m00 = m10 = m01 = 0.0
    for i in range(height):
        for j in range(width):
            if core[i, j]:
                w = 1.0
            elif band[i, j]:
                norm = _square_colours(lin, core, ring, i, j, fg0, bg0, fg, bg)
                if norm <= 0.0:
                    return 0.0, 0.0, 0.0
                w = _coverage_share(lin[i, j], blob[i, j], fg, bg, norm, local_contrast)
            else:
                weights[i, j] = 0.0
                continue
            weights[i, j] = w
            m00 += w
            m10 += w * j
            m01 += w * i
    return m00, m10, m01


@njit("void(float32[:, ::1], float32, float32, uint8[:, ::1], int64, int64, int64)",
      cache=True, nogil=True, error_model="numpy")
def cut_levels(roi: np.ndarray, low: np.float32, high: np.float32, part_mask: np.ndarray,
               x0: int, y0: int, margin: int) -> None:  # pragma: no cover
    """In place: ``roi`` less ``low``, within 0..``high - low``, and 0 where no pixel of
    ``part_mask`` (nonzero: the part) lies within ``margin`` pixels (the square around it) of
    the frame pixel under the ROI pixel: ROI pixel (i, j) lies on frame pixel (y0 + i, x0 + j);
    beyond the frame there is no part."""
    height, width = roi.shape
    frame_h, frame_w = part_mask.shape
    top = high - low
    for i in range(height):
        for j in range(width):
            value = roi[i, j] - low
            if value <= 0.0:
                roi[i, j] = 0.0
                continue
            y, x = y0 + i, x0 + j
            near = 0 <= y < frame_h and 0 <= x < frame_w and part_mask[y, x] != 0
            if not near:
                for yy in range(max(y - margin, 0), min(y + margin + 1, frame_h)):
                    for xx in range(max(x - margin, 0), min(x + margin + 1, frame_w)):
                        if part_mask[yy, xx] != 0:
                            near = True
                            break
                    if near:
                        break
            roi[i, j] = min(value, top) if near else 0.0


@njit(["float64[::1](float32[::1], float64[:, ::1], float64[::1], float64[:, ::1], float64[::1])",
       "float64[::1](float64[::1], float64[:, ::1], float64[::1], float64[:, ::1], float64[::1])"],
      cache=True, nogil=True, error_model="numpy")
def mlp_forward(x: np.ndarray, w0: np.ndarray, b0: np.ndarray, w1: np.ndarray,
                b1: np.ndarray) -> np.ndarray:  # pragma: no cover
    """One input vector through a network of one tanh hidden layer: w1 tanh(w0 x + b0) + b1
    (every network of the default pipeline; ``mlp.NumpyMLP`` takes this path for them)."""
    hidden = np.empty(w0.shape[0])
    for i in range(w0.shape[0]):
        s = b0[i]
        for j in range(w0.shape[1]):
            s += w0[i, j] * x[j]
        hidden[i] = np.tanh(s)
    out = np.empty(w1.shape[0])
    for o in range(w1.shape[0]):
        s = b1[o]
        for i in range(w1.shape[1]):
            s += w1[o, i] * hidden[i]
        out[o] = s
    return out


@njit("float32[:, ::1](uint8[:, :, ::1], float32[::1], float32[::1], float32[:, ::1], "
      "float32[:, :, ::1], float32[::1], float32)", cache=True, nogil=True, error_model="numpy")
def colour_likeness(image: np.ndarray, log_lut: np.ndarray, ref: np.ndarray,
                    means: np.ndarray, icovs: np.ndarray, consts: np.ndarray,
                    inv_scale: np.float32) -> np.ndarray:  # pragma: no cover
    """``part_colour.PartColour.image`` in one pass: each pixel's log colour (``log_lut``)
    over the frame's (``ref``), its log density under Gaussian 0 (the part's) against the
    largest under the others (the table's: mean, inverse covariance, constant each), through
    the logistic ``255 / (1 + exp(-ratio * inv_scale))``, the ratio clipped to +-30."""
    height, width = image.shape[0], image.shape[1]
    out = np.empty((height, width), np.float32)
    count = means.shape[0]
    for i in range(height):
        for j in range(width):
            x0 = log_lut[image[i, j, 0]] - ref[0]
            x1 = log_lut[image[i, j, 1]] - ref[1]
            x2 = log_lut[image[i, j, 2]] - ref[2]
            part = np.float32(0.0)
            table = np.float32(-np.inf)
            for k in range(count):
                d0 = x0 - means[k, 0]
                d1 = x1 - means[k, 1]
                d2 = x2 - means[k, 2]
                a = icovs[k]
                q = (a[0, 0] * d0 * d0 + a[1, 1] * d1 * d1 + a[2, 2] * d2 * d2
                     + np.float32(2.0) * (a[0, 1] * d0 * d1 + a[0, 2] * d0 * d2
                                          + a[1, 2] * d1 * d2))
                density = consts[k] - np.float32(0.5) * q
                if k == 0:
                    part = density
                elif density > table:
                    table = density
            ratio = min(max((part - table) * inv_scale, np.float32(-30.0)), np.float32(30.0))
            out[i, j] = np.float32(255.0) / (np.float32(1.0) + np.exp(-ratio))
    return out
