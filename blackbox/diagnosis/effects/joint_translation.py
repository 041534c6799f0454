"""``joint_translation``: a declared joint's branches are not tied rigidly in translation.

Cut: the RBE2 (CM=123) that ties the joint's branch grids to its first grid is removed for those
branches, and each translation is bridged by a spring ``K0`` (the smaller of the two branches'
own stiffness there). Released, as the data support (:func:`~blackbox.diagnosis.effects.connection.branch_ladder`):
"equal" (``kt_J``: one factor on that stiffness along every global axis), "per-axis" (``ktx_J,
kty_J, ktz_J``: equal springs between every pair of branches along each axis) or "per-branch"
(``ktx_J_G`` ...: per axis, a spring from each branch grid ``G`` to the joint's centre; three
or more branches). A joint whose tie is not one RBE2 CM=123 on its
first grid has no candidate. A branch grid with no member (a clamped footing: the joint is the
structure's support) is bridged with the other branch's stiffness.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from blackbox.diagnosis.effects.connection import Connection, branch_ladder
from blackbox.diagnosis.effects.registry import register

__all__ = ["JointTranslation"]


@register
@dataclass(frozen=True, eq=False)
class JointTranslation(Connection):
    kind = "joint_translation"
    summary = "a declared joint's branches move apart in translation (springs instead of its RBE2 tie)"

    @classmethod
    def cut(cls, editor, ctx) -> list["JointTranslation"]:
        d = editor.deck
        out = []
        at = editor.members_at
        for jc in ctx.joints:
            g1, others = jc.grids[0], set(jc.grids[1:])
            ties = [r for r in d.rbe2s.values() if r.gn == g1 and others & set(r.gm)]
            if not ties or any(sorted(r.cm) != ["1", "2", "3"] for r in ties):
                continue
            # each branch grid's own stiffness along each axis: the members ending there (a
            # branch may be a clamped footing with none: a joint that is the structure's support)
            own = {g: [sum(editor.kdiag(e, g, c) for e in at.get(g, ())) for c in (1, 2, 3)] for g in jc.grids}
            if not any(at.get(g) for g in jc.grids):
                continue
            for r in ties:
                gm = tuple(x for x in r.gm if x not in others)
                if gm:
                    d.rbe2s[r.eid] = replace(r, gm=gm)
                else:
                    del d.rbe2s[r.eid]
            idx, k_ref = [], []
            for c in (1, 2, 3):
                ks = []
                for gi in jc.grids[1:]:
                    pair = (own[gi][c - 1], own[g1][c - 1])
                    # a branch with nothing there (no member, or a pin flag releasing that
                    # translation): the other branch's stiffness sizes the cut
                    k0 = min(pair) if min(pair) > 1e-6 * max(pair) else max(pair)
                    idx.append(editor.connect(k0, (gi, c), (g1, c)))
                    ks.append(k0)
                k_ref.append(float(np.mean(ks)))
            ladder = branch_ladder(len(jc.grids), np.array(k_ref),
                                   (f"ktx_{jc.name}", f"kty_{jc.name}", f"ktz_{jc.name}"), f"kt_{jc.name}",
                                   tuple(str(g) for g in jc.grids))
            out.append(cls.on_ladder((jc.name,), idx, ladder))
        return out
