"""A measurement of the crack network by parastichy: of each lattice direction's springs, how many
are cracked (broken), and how far apart its cracks lie along the trunk."""
import attrs
import numpy as np

from bark.contract.strategies import Analysis, Analyzer


@attrs.frozen(kw_only=True)
class CracksByParastichy(Analyzer):
    """Per lattice offset (parastichy): springs, cracks, the cracked share and the mean height
    between neighbouring cracks (length units).  A photograph, without springs, has none."""

    reads_springs = True

    def analyze(self, points, patches, springs):
        if springs is None:
            return Analysis(summary={})
        offset = springs.pairs[:, 1].astype(np.int64) - springs.pairs[:, 0]
        rows = []
        for o in springs.offsets:
            mine, cracked = offset == o, (offset == o) & ~springs.intact
            z = np.sort(points[springs.pairs[cracked, 0], -1])
            rows.append({"offset": int(o), "springs": int(mine.sum()), "cracks": int(cracked.sum()),
                         "cracked_share": float(cracked.sum() / max(mine.sum(), 1)),
                         "crack_spacing": float(np.mean(np.diff(z))) if z.size > 1 else None})
        return Analysis(summary={f"cracked_share_{r['offset']}": r["cracked_share"] for r in rows},
                        tables={"by_parastichy": rows})
