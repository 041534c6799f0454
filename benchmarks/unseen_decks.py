"""Public decks ``blackbox import`` was not written against: how many it imports and solves,
and how the solution agrees with MYSTRAN's (issue 20's last target).

    python benchmarks/unseen_decks.py --collect FOLDER --mirror OWNER/NAME=GITDIR ...
    python benchmarks/unseen_decks.py FOLDER [--half tuning|held-out] [--no-mystran]
    python benchmarks/unseen_decks.py FOLDER2 --second --collect --mirror OWNER/NAME=GITDIR ...
    python benchmarks/unseen_decks.py FOLDER2 --second [--no-mystran]
    python benchmarks/unseen_decks.py FOLDER3 --third [--collect --mirror ...]
    python benchmarks/unseen_decks.py FOLDER4 --fourth [--collect --mirror ...]
    python benchmarks/unseen_decks.py FOLDER5 --fifth [--collect --mirror ...]
    python benchmarks/unseen_decks.py FOLDER --second ... --as-static

The decks (``DECKS`` below) are every whole input file (a CEND and a BEGIN BULK) of four public
repositories, at the commits of ``COMMITS``, that has a line element (CBAR, CBEAM, CROD, CONROD,
CTUBE, CELAS*, CBUSH*, CGAP, ...) and no shell or solid (CQUAD*, CTRIA*, CHEXA, CPENTA, CTETRA,
CSHEAR, ...; INCLUDEd files counted), less: decks of ``tests/data/decks`` (the corpus the import
was written against), exact copies, and variants of one deck that differ only in solver options
(MYSTRAN's benchmark copies each test run as ``SB-``/``SS-`` and its modal runs per eigensolver:
``-GIV``, ``-INV``, ``-LANCZOS...``, ``-MGIV``; the first in sorted order is kept), and decks whose
INCLUDE is not in the repository. ``--collect`` copies them out of git mirrors of those
repositories (``git show COMMIT:PATH``) into ``FOLDER/OWNER+NAME/PATH``.

The list is split once, before any change to the import was made for it, into a tuning half and a
held-out half: ``random.Random(20).shuffle`` of the list, the first half tuning (``split()``).
The import was changed looking at the tuning half's failures only.

A second corpus, ``--second`` (``decks_second.csv``: repository, commit, path), was collected on
2026-11-27, after the import had been changed for both halves above, and was run once before
any change for it: every whole input file with a line element and no shell or solid (as above)
of ten further public repositories (NASA's COSMIC NASTRAN-95 and -93 demonstration decks, a
MATLAB NASTRAN clone's verification decks, FEMAP exports, an FE library's and a structural
dynamics toolbox's test decks, ...), at most 40 per repository in sorted path order, less exact
copies of the first corpus and of each other (line endings and trailing blanks aside). The list
names the commit of each; ``--second --collect`` copies them to ``FOLDER2/OWNER+NAME/PATH``
with the files their INCLUDEs name.

A third corpus, ``--third`` (``decks_third.csv``), was collected on 2026-11-27 by the same rule
from nine more public repositories, found and fetched for it (course decks, an OpenMDAO NASTRAN
wrapper's tests, DMAP examples, a MYSTRAN pre-processor's exports, ...; every other repository
searched had no such deck), and run once before any change for it.

A fourth corpus, ``--fourth`` (``decks_fourth.csv``), was collected on 2026-11-27 by the same rule
from repositories used by none of the three above nor searched for them, by a helper that did
not run the import on them, and run once before any change for it.

A fifth corpus, ``--fifth`` (``decks_fifth.csv``), was collected the same way on 2026-11-27 from
thirteen further repositories (125 tried), the four lists above and their forks excluded.

For each deck, one row: the half, whether ``blackbox import`` accepts it (else the first line of
its message), the subcases imported, and the largest difference of the reference solver's
displacements from MYSTRAN's, relative to each subcase's largest translation (rotation):

* ``deck``: MYSTRAN 18 running the original input file (its folder copied), for SOL 1/101 decks
  it runs (not with PARAM,INREL,-1: MYSTRAN has no inertia relief; not a deck with a DMIG, which
  MYSTRAN skips with a warning only); the deck's own output requests decide which subcases and
  grids are compared; a subcase whose MYSTRAN displacements are all zero while ours are not is a
  disagreement (1.0);
* ``study``: otherwise (the deck's solution is not static, or MYSTRAN fails on the original), the
  mystran adapter solving the imported study (model.bdf and loads.csv), which checks the reference
  solve but not the import's reading of the load cards (for a study with enforced
  displacements the adapter picks MYSTRAN's band solver: ``solver_adapters.nastran.banded_solver``);
* ``-``: MYSTRAN runs neither (a card it does not run: CBEAM, PLOAD1, ...).

``--as-static`` takes the decks with no static load case instead (modal, flutter, trim decks),
each made a linear static one (:func:`as_static`: a unit force at its first grid in an added
subcase; the copy is written beside the deck, for its INCLUDEs, and removed): whether their bulk
data imports and solves, without MYSTRAN.

A summary line per half counts the decks accepted, those solved (the reference solver solves every
case), those with a static load case (not stopped by "no static load case to import") and the
solved share of them, and the disagreements above 1e-6.
"""

from __future__ import annotations

import argparse
import posixpath
import random
import re
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path, PurePosixPath

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from deck_corpus import _mystran, _solve                  # noqa: E402
from blackbox.commands import import_deck                  # noqa: E402

RTOL = 1e-6
SEED = 20

COMMITS = {
    'Alneos/vega': '91b1e6516a43e55741b0bc21e5fff8dce2240116',
    'MYSTRANsolver/MYSTRAN': '77d970d543961f549b168a9e2431fd30572331eb',
    'MYSTRANsolver/MYSTRAN_Benchmark': 'ad765adfcd2e2fd148743f0846d6ce6e71d33c99',
    'SteveDoyle2/pyNastran': '1d25a92442a76cd1b24bfd0bd4008644b79322b2',
}
DECKS = [  # (repository, deck, its INCLUDEd files)
    ('Alneos/vega', 'testdata/nastran/alneos/rbar1mod/rbar1mod.dat', ()),
    ('Alneos/vega', 'testdata/nastran/alneos/rod1freeforce/rod1freeforce.dat', ()),
    ('Alneos/vega', 'testdata/nastran/caw/prob30c/prob30c.dat', ()),
    ('Alneos/vega', 'testdata/nastran/irt/2dof108/2dof108.bdf', ()),
    ('Alneos/vega', 'testdata/nastran/irt/cantibeam/cantibeam.nas', ()),
    ('Alneos/vega', 'testdata/nastran/irt/cbush1/cbush1.bdf', ()),
    ('Alneos/vega', 'testdata/nastran/irt/cbush1b/cbush1b.bdf', ()),
    ('Alneos/vega', 'testdata/nastran/irt/dmigstfl/dmigstfl.nas', ()),
    ('Alneos/vega', 'testdata/nastran/irt/dmigstfs/dmigstfs.nas', ()),
    ('Alneos/vega', 'testdata/nastran/irt/grav-coord/grav-coord.nas', ()),
    ('Alneos/vega', 'testdata/nastran/irt/n4w101/n4w101.nas', ()),
    ('Alneos/vega', 'testdata/nastran/irt/nas101prob2/nas101prob2.dat', ()),
    ('Alneos/vega', 'testdata/nastran/irt/nas102prob12/prob12.nas', ()),
    ('Alneos/vega', 'testdata/nastran/irt/nas102prob14a/nas102prob14a.nas', ()),
    ('Alneos/vega', 'testdata/nastran/irt/nas103prob1c/nas103prob1c.nas', ()),
    ('Alneos/vega', 'testdata/nastran/irt/nas103prob3/nas103prob3.nas', ()),
    ('Alneos/vega', 'testdata/nastran/irt/nas103prob4a/nas103prob4a.nas', ()),
    ('Alneos/vega', 'testdata/nastran/irt/nas120probF/nas120probF.nas', ()),
    ('Alneos/vega', 'testdata/nastran/irt/sdld21b/sdld21b.bdf', ()),
    ('Alneos/vega', 'testdata/nastran/irt/sdld27a/sdld27a.bdf', ()),
    ('Alneos/vega', 'testdata/nastran/irt/sdld27a_pvisc/sdld27a_pvisc.bdf', ()),
    ('Alneos/vega', 'testdata/nastran/irt/sine_test/sine_test.nas', ()),
    ('Alneos/vega', 'testdata/nastran/irt/ssll11a/ssll11a.nas', ()),
    ('Alneos/vega', 'testdata/nastran/irt/ssll11c/ssll11c.nas', ()),
    ('Alneos/vega', 'testdata/nastran/irt/truss1/truss1.nas', ()),
    ('Alneos/vega', 'testdata/nastran/irt/truss3/truss3.nas', ()),
    ('MYSTRANsolver/MYSTRAN', 'Build_Test_Cases/buckling/bar.bdf', ()),
    ('MYSTRANsolver/MYSTRAN', 'Build_Test_Cases/statics/bar_static_large.bdf', ()),
    ('MYSTRANsolver/MYSTRAN', 'Build_Test_Cases/statics/bar_tube.bdf', ()),
    ('MYSTRANsolver/MYSTRAN', 'Build_Test_Cases/statics/bar_tube2.bdf', ()),
    ('MYSTRANsolver/MYSTRAN', 'Build_Test_Cases/statics/bar_tube_dollar.bdf', ()),
    ('MYSTRANsolver/MYSTRAN', 'Build_Test_Cases/statics/missing_continuation.bdf', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bar_01.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bar_02.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bar_03.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bar_04.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bar_05.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bar_06.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bar_11.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bar_12.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bar_13.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bar_14.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bar_15.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bar_16.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bar_17.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_01.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_02.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_03.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_04.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_05.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_06.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_07.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_08.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_09.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_10.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_11.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_12.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_13.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_14.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_15.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_16.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_51.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_52.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/bush_53.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/case_0001.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/case_0002.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/Bush_Bar/case_0003.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/EB-BAR-CC-GIV.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/EB-BAR-FF-GIV.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/EB-GUYAN-03-GIV.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-BAR-10-BUCKLING-CF-LOAD-LAN-3D.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-BAR-10-BUCKLING-CF-LOAD-LAN.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-BAR-AUTOSPC-CHECK.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-BAR-RFORCE-OFFSET.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-BAR-TE-TEST.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-BAR-THERM-CONSTR.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-BAR-THERM-FREE.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-CONM2A.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-CORD3-0.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-GUYAN-01-FULL.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-GUYAN-01-SPARSE.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-RADIAL-BARS-CYL-GLOBAL-END-LOADS.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-RADIAL-BARS-CYL-GLOBAL-RB-DISP.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-RBE2-01-CBAR-01.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-RBE2-01-CROD-03.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-RBE2-01-CROD-05-MPC-03.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-RBE3-01-CBAR-08.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-RODDISPL-N-LOAD.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-RODLOAD-MPC-FOR-SING.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-SOLVE_EQNS_1_GRID.DAT', ()),
    ('MYSTRANsolver/MYSTRAN_Benchmark', 'Benchmark_Decks/SB-SOLVE_EQNS_1_SEQGP.DAT', ()),
    ('SteveDoyle2/pyNastran', 'docs/pyNastran_in_MATLAB_example/BAH_Plane.bdf', ('docs/pyNastran_in_MATLAB_example/bah_Pstructure.dat', 'docs/pyNastran_in_MATLAB_example/bah_Paero.dat', 'docs/pyNastran_in_MATLAB_example/bah_Pinterface.dat')),
    ('SteveDoyle2/pyNastran', 'models/aero/aerobeam.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/aero/bah_plane/bah_plane2.bdf', ('models/aero/bah_plane/structure_bah.inc', 'models/aero/bah_plane/aero_bah.inc', 'models/aero/bah_plane/interface_bah.inc')),
    ('SteveDoyle2/pyNastran', 'models/aero/bah_plane/bah_plane_qhh.bdf', ('models/aero/bah_plane/structure_bah.inc', 'models/aero/bah_plane/aero_bah.inc', 'models/aero/bah_plane/interface_bah.inc')),
    ('SteveDoyle2/pyNastran', 'models/aero/cpmopt.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/aero/fmondsp.dat', ()),
    ('SteveDoyle2/pyNastran', 'models/aero/monpnt3/BAH_Plane_cont_gust_LINE5000000_10FREQs.bdf', ('models/aero/monpnt3/bah_Pstructure.dat', 'models/aero/monpnt3/bah_Paero.dat', 'models/aero/monpnt3/bah_Pinterface.dat')),
    ('SteveDoyle2/pyNastran', 'models/aero/pt145.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/aero/zona/f16_ma41.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/aero/zona/ztran.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/bar3truss/vared_bar3.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/beam_modes/beam_modes.dat', ('models/beam_modes/cbar_cbeam.blk',)),
    ('SteveDoyle2/pyNastran', 'models/beam_modes/cbarao_cbeam_modes.bdf', ('models/beam_modes/cbarao_cbeam.blk',)),
    ('SteveDoyle2/pyNastran', 'models/beam_modes/cbarao_cbeam_static.bdf', ('models/beam_modes/cbarao_cbeam.blk',)),
    ('SteveDoyle2/pyNastran', 'models/bugs/euler_column_linear_buckling/euler_column_linear_buckling.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/bugs/msc_2014/sdof_crod.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/cbush_psd_bug/pn_mwe_s-sol_111.dat', ()),
    ('SteveDoyle2/pyNastran', 'models/frame_three_bars/bar1.dat', ()),
    ('SteveDoyle2/pyNastran', 'models/freq_sine/bad_sine.dat', ()),
    ('SteveDoyle2/pyNastran', 'models/freq_sine/good_sine.dat', ()),
    ('SteveDoyle2/pyNastran', 'models/msc/force_vector/nas102_ws21.dat', ()),
    ('SteveDoyle2/pyNastran', 'models/nx/rotor/rotor049.dat', ()),
    ('SteveDoyle2/pyNastran', 'models/nx/z402cdamp1_04.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/other/ab4.dat', ()),
    ('SteveDoyle2/pyNastran', 'models/other/ar29sadl.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/other/b3bend.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/other/dbxdra7.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/other/htrussx.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/other/mdb200.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/other/sdbush01.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/other/sdr11se_s2dclg.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/other/tst1d3.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/other/v10601s.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/other/v12902.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/satk/pn_mwe_s-solution_1.dat', ()),
    ('SteveDoyle2/pyNastran', 'models/sol200/model_200.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/superelements/se_test_static/se_test_n11_static_10_cases.bdf', ('models/superelements/se_test_static/incl/n11_fem.bdf', 'models/superelements/se_test_static/incl/se/se_test_n11.asm', 'models/superelements/se_test_static/incl/se/se_test_n11.pch')),
    ('SteveDoyle2/pyNastran', 'models/transfer_function/actuator_tf_modeling.bdf', ()),
    ('SteveDoyle2/pyNastran', 'models/unit/cbush/cbush.dat', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/bdf/cards/aero/examples/flutter/case6/agardztran.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/bdf/cards/aero/examples/mloads/case1/ha144ds.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/bdf/test/unit/obscure/d200pe10.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/bdf/test/unit/obscure/degvcn03.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/cbar.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/cbar_modes.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/cbeam.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/celas1.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/celas3.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/celas4.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/celas_mpc_series.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/conrod.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/crod.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/crod_aset.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/crod_axial.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/crod_mpc.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/crod_torsion.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/ctube.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/freq_direct_response.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/freq_response.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/inrel_test.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/test_ese_all_springs.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/dev/bdf_vectorized3/solver/test/examples/test_ese_cantilever.solver.bdf', ()),
    ('SteveDoyle2/pyNastran', 'pyNastran/op2/test/examples/cbush_nonlinear/cbush_106_large_disp.bdf', ()),
]


def split() -> dict[tuple[str, str], str]:
    """(repository, deck) -> "tuning" or "held-out": the seeded shuffle of DECKS, halved."""
    order = [(r, p) for r, p, _ in DECKS]
    random.Random(SEED).shuffle(order)
    half = (len(order) + 1) // 2
    return {key: ("tuning" if i < half else "held-out") for i, key in enumerate(order)}


def collect(folder: Path, mirrors: dict[str, str]) -> None:
    for repo, path, includes in DECKS:
        git = mirrors[repo]
        for p in (path, *includes):
            out = folder / repo.replace("/", "+") / p
            out.parent.mkdir(parents=True, exist_ok=True)
            data = subprocess.run(["git", "--git-dir", git, "show", f"{COMMITS[repo]}:{p}"],
                                  capture_output=True, check=True).stdout
            out.write_bytes(data)


_INCLUDE_LINE = re.compile(rb"^[ \t]*INCLUDE[ \t]+'([^']+)'", re.I | re.M)


def collect_second(folder: Path, mirrors: dict[str, str], corpus: str = "second") -> None:
    """A listed corpus (``decks_second.csv`` ... ``decks_fifth.csv``) out of git mirrors, each deck
    at its commit, with the files its INCLUDE lines name (relative to the including file's
    folder, recursively)."""
    import csv
    with open(Path(__file__).with_name(f"decks_{corpus}.csv"), newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        todo, seen = [r["path"]], set()
        while todo:
            p = todo.pop()
            if p in seen:
                continue
            seen.add(p)
            got = subprocess.run(["git", "--git-dir", mirrors[r["repo"]], "show", f"{r['commit']}:{p}"],
                                 capture_output=True)
            if got.returncode:
                continue                        # an INCLUDE outside the repository: the row says so
            out = folder / r["repo"].replace("/", "+") / p
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_bytes(got.stdout)
            base = posixpath.dirname(p)
            for m in _INCLUDE_LINE.finditer(got.stdout):
                name = m.group(1).decode("utf-8", "replace").strip().replace("\\", "/")
                todo.append(posixpath.normpath(posixpath.join(base, name)))


def _study_mystran(result):
    """The mystran adapter on the imported study: {case: {grid: [6 values]}}, None when it does
    not run, or the text "lost" when MYSTRAN's AUTOSPC took a load (its grid-level singularity
    test before the SPCs differs from the reference solver's after them, docs/mystran.md)."""
    from blackbox.adapters import make_adapter_for
    from blackbox.study import load_study
    with tempfile.TemporaryDirectory() as tmp:
        result.write(Path(tmp))
        try:
            study = load_study(Path(tmp))
            adapter = make_adapter_for(study, "mystran", cache=False)
            report = list(adapter.dofs())
            with warnings.catch_warnings(record=True) as seen:
                warnings.simplefilter("always")
                out = adapter.solve(study.loads, report)
        except Exception:
            return None
    if any("MYSTRAN's AUTOSPC took load" in str(w.message) for w in seen):
        return "lost"
    tables: dict[int, dict[int, list[float]]] = {}
    for j, case in enumerate(out.cases):
        if not case.lstrip("-").isdigit():
            continue
        table = tables.setdefault(int(case), {})
        for i, (g, c) in enumerate(report):
            table.setdefault(g, [0.0] * 6)[c - 1] = float(out.values[i, j])
    return tables


def agreement(cases, report, u, tables, size: float) -> float | None:
    """The largest difference over the subcases MYSTRAN printed, relative to the subcase's largest
    translation (rotation). A part (translations or rotations) is compared only when it is not
    round-off: rotations when their largest times the model's size is above 1e-9 of the largest
    translation, and the other way round (a pure axial load leaves rotations of 1e-18, printed as
    noise by both solvers, and relative to that noise any difference is large)."""
    worst, compared = 0.0, 0
    index = {d: i for i, d in enumerate(report)}
    for j, case in enumerate(cases):
        table = tables.get(int(case)) if case.lstrip("-").isdigit() else None
        if not table:
            continue
        grids = [g for g in sorted(table) if (g, 1) in index]
        if not grids:
            continue
        ours = np.array([[u[index[(g, c)], j] if (g, c) in index else 0.0 for c in range(1, 7)]
                         for g in grids])
        ref = np.array([table[g] for g in grids])
        if not np.abs(ref).any():
            # MYSTRAN's displacements all zero (a card it skipped took the load path away):
            # a disagreement when ours are not, never an agreement
            worst = max(worst, 1.0 if np.abs(ours).any() else 0.0)
            compared += 1
            continue
        t, r = np.abs(ref[:, :3]).max(), np.abs(ref[:, 3:]).max() * size
        for part, scale, other in ((slice(0, 3), t, r), (slice(3, 6), r, t)):
            if scale > 0.0 and scale > 1e-9 * other:
                worst = max(worst, float(np.abs(ours[:, part] - ref[:, part]).max()
                                         / np.abs(ref[:, part]).max()))
        compared += 1
    return worst if compared else None


def _size(deck) -> float:
    xyz = np.array([g.xyz for g in deck.grids.values()]) if deck.grids else np.zeros((1, 3))
    return max(float(np.ptp(xyz, axis=0).max()), 1e-300)


def row(path: Path, use_mystran: bool = True) -> tuple[str, str, str, float | None]:
    """(accepted, subcases, agreement text, agreement value)."""
    try:
        result = import_deck.run(path)
    except Exception as exc:            # the row says why the deck is not accepted
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        return f"no: {first.replace(str(path), path.name)[:160]}", "", "", None
    try:
        cases, report, u = _solve(result)
    except Exception as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        return "imported, not solved: " + first[:140], str(len(result.cases)), "", None
    if not use_mystran:
        return "yes", str(len(cases)), "", None
    value, source = None, ""
    size = _size(result.deck)
    from solver_adapters.casecontrol import read_case_control
    cc = read_case_control(path.read_text(errors="replace"), str(path))
    # MYSTRAN has no inertia relief: on a deck with PARAM,INREL,-1 it would solve the loads as
    # applied with the SUPORT DOFs held, not the balanced loads NASTRAN solves; and MYSTRAN 18
    # skips a DMIG with a warning only (docs/mystran.md): the original deck is then another
    # structure, and the mystran adapter refuses the study
    relieved = any(n.startswith("inertia relief") for n in result.notes)
    # and MYSTRAN 18 reads RFORCE's A in radians per unit time (NASTRAN: revolutions; measured on
    # SB-BAR-RFORCE-OFFSET.DAT, docs/import.md) and reads SPCD without applying it: a deck with
    # either is compared as a study
    dialect = re.search(r"^[ \t]*(RFORCE|SPCD)[ \t,*]", path.read_text(errors="replace"), re.M | re.I)
    if cc is not None and cc.sol.upper() in ("1", "101", "SESTATIC", "SESTATICS", "STATICS") and not relieved \
            and not getattr(result.deck, "dmigs", None) and not dialect:
        tables = _mystran(path)
        if tables:
            value, source = agreement(cases, report, u, tables, size), "deck"
    if value is None:
        tables = _study_mystran(result)
        if tables == "lost":
            return "yes", str(len(cases)), "- (MYSTRAN's AUTOSPC took a load: not compared)", None
        if tables:
            value, source = agreement(cases, report, u, tables, size), "study"
    shown = f"{value:.1e} ({source})" if value is not None else "-"
    return "yes", str(len(cases)), shown, value


def as_static(path: Path) -> Path | None:
    """A copy of the deck ``path`` made a linear static one, beside it (so that its INCLUDEs
    resolve; the caller removes it): ``SOL 101`` and one added subcase 999999 loaded by a unit
    force along (1, 1, 1) at the first GRID of the file, ``LOAD = 999999``. ``None``: the file
    has no GRID card or no BEGIN BULK of its own."""
    text = path.read_text(errors="replace")
    g = re.search(r"^GRID\*?[ ,\t]+\*?\s*(\d+)", text, re.M | re.I)
    bulk = re.search(r"^\s*BEGIN\s+BULK.*$", text, re.M | re.I)
    if not g or not bulk:
        return None
    head = text[:bulk.start()]
    head = (re.sub(r"^(\s*SOL\s+)\S+.*$", r"\g<1>101", head, count=1, flags=re.M | re.I)
            if re.search(r"^\s*SOL\s", head, re.M | re.I) else "SOL 101\n" + head)
    out = path.with_name(path.stem + "__static" + path.suffix)
    out.write_text(head + "SUBCASE 999999\n  LOAD = 999999\n" + text[bulk.start():bulk.end()]
                   + f"\nFORCE,999999,{g.group(1)},0,1.0,1.,1.,1.\n" + text[bulk.end():])
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("--collect", action="store_true", help="copy the decks out of git mirrors")
    ap.add_argument("--mirror", action="append", default=[], help="OWNER/NAME=GITDIR")
    ap.add_argument("--half", choices=("tuning", "held-out"))
    ap.add_argument("--no-mystran", action="store_true")
    ap.add_argument("--only", help="decks whose path contains this text")
    ap.add_argument("--second", action="store_true", help="the second corpus (decks_second.csv)")
    ap.add_argument("--third", action="store_true", help="the third corpus (decks_third.csv)")
    ap.add_argument("--fourth", action="store_true", help="the fourth corpus (decks_fourth.csv)")
    ap.add_argument("--fifth", action="store_true", help="the fifth corpus (decks_fifth.csv)")
    ap.add_argument("--as-static", action="store_true",
                    help="the decks with no static load case only, each made static (as_static: a unit "
                         "force in an added subcase, written beside the deck and removed): does its bulk "
                         "data import and solve? (no MYSTRAN comparison)")
    a = ap.parse_args(argv)
    listed = ("fifth" if a.fifth else "fourth" if a.fourth else "third" if a.third else "second" if a.second
              else None)
    mirrors = dict(m.split("=", 1) for m in a.mirror)
    if a.collect:
        collect_second(a.folder, mirrors, listed) if listed else collect(a.folder, mirrors)
        return 0
    halves = split()
    decks = DECKS
    if listed:
        import csv
        with open(Path(__file__).with_name(f"decks_{listed}.csv"), newline="") as f:
            decks = [(r["repo"], r["path"], ()) for r in csv.DictReader(f)]
        halves = {(r, p): listed for r, p, _ in decks}
    print("| deck | source | half | accepted | subcases | agreement |\n|---|---|---|---|---|---|")
    tally: dict[str, list[int]] = {}
    bad = []
    for repo, p, _ in decks:
        half = halves[(repo, p)]
        if (a.half and half != a.half) or (a.only and a.only not in p):
            continue
        path = a.folder / repo.replace("/", "+") / p
        if a.as_static:
            try:                        # only the decks the import stops for want of a static case
                import_deck.run(path)
                continue
            except Exception as exc:
                if "no static load case to import" not in str(exc):
                    continue
            made = as_static(path)
            if made is None:
                accepted, n, shown, value = "not made static (no GRID or BEGIN BULK in the file)", "", "", None
            else:
                try:
                    accepted, n, shown, value = row(made, False)
                finally:
                    made.unlink()
        else:
            accepted, n, shown, value = row(path, not a.no_mystran)
        t = tally.setdefault(half, [0, 0, 0, 0, 0])
        t[0] += 1
        t[4] += "no static load case to import" in accepted
        t[1] += accepted.startswith(("yes", "imported"))
        t[2] += accepted == "yes"
        if value is not None and value > RTOL:
            t[3] += 1
            bad.append(p)
        print(f"| `{PurePosixPath(p).name}` | {repo} `{p}` | {half} | {accepted} | {n} | {shown} |", flush=True)
    for half, (total, imported, solved, disagree, no_load) in sorted(tally.items()):
        if a.as_static:
            print(f"\n{half}, made static: {solved} of {total} decks with no static load case import and "
                  f"solve ({imported} import)")
            continue
        static = total - no_load
        print(f"\n{half}: {solved} of {total} imported and solved ({imported} imported); "
              f"{static} have a static load case, {solved} of them solved "
              f"({100 * solved / max(static, 1):.0f} %); {disagree} disagree above {RTOL:g}")
    for p in bad:
        print(f"disagreement: {p}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
