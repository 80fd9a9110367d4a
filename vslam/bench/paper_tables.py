"""Seed 001's Tables IV and V in the paper's layout, with the paper's figures beside ours."""
from __future__ import annotations

from vslam.evaluation.tables import format_table

# Table IV: start-to-end pose difference (dx m, dy m, dtheta rad) of visual odometry and of VSLAM, modes 2-6 (the
# paper's VO could not run on mode 1)
PAPER_TABLE_IV = {2: ((17.35, -6.58, -0.86), (0.0725, -0.0088, 0.0075)),
                  3: ((-4.36, 1.27, 0.03), (0.0355, -0.0115, 0.0001)),
                  4: ((0.22, 0.19, -0.13), (0.0359, -0.0149, 0.0086)),
                  5: ((1.01, 0.09, -0.17), (0.0302, -0.0011, -0.0249)),
                  6: ((2.10, 0.00, -0.23), (0.0221, -0.0056, -0.0128))}
# Table V: storage of all 7154 descriptors (MB) and time to match the last image against all previous ones (s)
PAPER_TABLE_V = {2: (7.67, 4.23), 3: (14.63, 6.62), 4: (28.59, 9.62), 5: (56.55, 27.27), 6: (112.43, 58.32),
                 "SIFT": (1213.84, 1264.20)}


def _d(s2e: dict) -> str:
    """Our start-to-end difference as the paper reports it: the error of the end pose relative to the start."""
    return f"{s2e['error_dx']:+.3f} / {s2e['error_dy']:+.3f} / {s2e['error_dtheta']:+.3f}"


def _paper(mode: int, which: int) -> str:
    if mode not in PAPER_TABLE_IV:
        return "- (no VO in the paper)"
    return " / ".join(f"{v:+.4g}" for v in PAPER_TABLE_IV[mode][which])


def table_iv(runs, chain: dict) -> str:
    """Per mode: start-to-end dx / dy / dtheta (m, m, rad) of VO and SLAM, ours beside the paper's, and ATE."""
    rows = []
    for r in runs:
        rows.append([str(r.mode), _d(r.vo), _paper(r.mode, 0), _d(r.slam), _paper(r.mode, 1),
                     f"{r.vo_ate_m:.3f}", f"{r.slam_ate_m:.3f}", str(r.accepted), str(r.kept), str(r.false_kept),
                     str(r.kept_below_r), f"{r.fps:.1f}"])
    rows.append(["ORB chain", _d(chain["start_to_end"]), "-", "-", "-", f"{chain['ate_m']:.3f}", "-", "-", "-", "-",
                 "-", "-"])
    return ("Table IV: start-to-end pose error dx / dy / dtheta (m / m / rad); our VO is the same for every mode "
            "(it does not use the loop descriptor); a kept loop is false when its two footprints do not overlap at all "
            "(J = 0 at the true poses); those overlapping less than the paper's loop threshold are counted apart\n\n"
            + format_table(["mode", "VO (ours)", "VO (paper)", "SLAM (ours)", "SLAM (paper)", "VO ATE (m)",
                            "SLAM ATE (m)", "loops accepted", "kept", "false kept (J = 0)", "kept, 0 < J < 0.33",
                            "frames/s"], rows))


def table_v(storage: dict, sift: dict) -> str:
    """Per mode: storage of all descriptors (MB) and the time to match the last image against all previous ones (s),
    ours beside the paper's; our indexed query (global scan + verified shortlist, on the frames actually encoded,
    never scaled) too; SIFT measured here."""
    rows = []
    for m, s in storage.items():
        p = PAPER_TABLE_V.get(m)   # the paper has no mode 1 row
        paper_mb, paper_s = (f"{p[0]:.2f}", f"{p[1]:.2f}") if p else ("-", "-")
        rows.append([str(m), f"{s['storage_mb']:.2f}", paper_mb, f"{s['linear_s']:.2f}", paper_s,
                     f"{s['indexed_s'] * 1000:.1f}"])
    p = PAPER_TABLE_V["SIFT"]
    rows.append(["SIFT (OpenCV)", f"{sift['storage_mb']:.2f}", f"{p[0]:.2f}", f"{sift['linear_s']:.2f}",
                 f"{p[1]:.2f}", "-"])
    return ("Table V: storage of all descriptors and time to match the last image against all previous ones\n\n"
            + format_table(["mode", "storage MB (ours)", "storage MB (paper)", "linear match s (ours)",
                            "linear match s (paper)", "indexed query ms (ours)"], rows))
