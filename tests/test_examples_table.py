"""doc/examples.md stays true: every example folder of the reference tree (the published code's own runs) has its
rows, and each row's status holds (issue 30).

The walk: every folder under ``published_2025/multi_bodies/examples`` and ``published_2025/phoretic/multi_bodies/
examples``, and every input file in it (``*.dat``, ``*.inputfile``, not the runs' ``run*`` copies), must be a row
of the table.  A row "runs" must parse with the dynamic script's reader and load its override file from its
folder; "runs, GPU" must parse and name the ``pycuda`` backend; the test a row names must exist.  Negative
control: a folder missing from the table is found (a table without one row fails the walk).
"""
import ast
import re
from pathlib import Path

import pytest

from multi_bodies.files.input_options import read_input_file
from multi_bodies.run.run_setup import load_hooks

REPO = Path(__file__).resolve().parents[1]
TABLE = REPO / 'doc' / 'examples.md'
INPUT_LINE = re.compile(r'^\s*(scheme|structure|articulated)\s', re.M)  # what makes a file an input file
EXAMPLE_ROOTS = (('published_2025', 'multi_bodies', 'examples'),
                 ('published_2025', 'phoretic', 'multi_bodies', 'examples'))


def table_rows(text=None):
    """Rows (folder, input, status, test) of the marked table of doc/examples.md."""
    text = TABLE.read_text() if text is None else text
    body = text.split('<!-- examples table')[1].split('<!-- end of examples table -->')[0]
    rows = []
    for line in body.splitlines():
        cells = [c.strip() for c in line.strip().strip('|').split('|')]
        if len(cells) == 5 and cells[0].startswith('`'):
            rows.append((cells[0].strip('`'), cells[1].strip('`'), cells[2], cells[4].strip('`')))
    return rows


def reference_inputs(reference_dir):
    """(folder path, input file name) of every published input of the reference tree."""
    found = []
    for parts in EXAMPLE_ROOTS:
        root = reference_dir.joinpath(*parts)
        for folder in sorted(p for p in root.iterdir() if p.is_dir()):
            for path in sorted(folder.iterdir()):
                if path.suffix in ('.dat', '.inputfile') and not path.name.startswith('run') \
                        and INPUT_LINE.search(path.read_text(errors='replace')):
                    found.append((folder, path.name))
    return found


def missing_rows(reference_dir, rows):
    listed = {(folder, name) for folder, name, _, _ in rows}
    return [(f.name, n) for f, n in reference_inputs(reference_dir) if (f.name, n) not in listed]


def test_every_input_of_the_reference_tree_is_a_row(reference_dir):
    rows = table_rows()
    assert not missing_rows(reference_dir, rows)
    assert missing_rows(reference_dir, rows[1:]) == [(rows[0][0], rows[0][1])]  # negative control


def test_every_named_test_exists():
    for _, _, _, test in table_rows():
        path, name = test.split('::')
        tree = ast.parse((REPO / 'tests' / path).read_text())
        assert name in {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}, test


@pytest.mark.parametrize('row', table_rows(), ids=lambda row: '%s/%s' % row[:2])
def test_each_row_status_holds(row, reference_dir, monkeypatch):
    folder_name, input_name, status, _ = row
    folders = [reference_dir.joinpath(*parts, folder_name) for parts in EXAMPLE_ROOTS]
    folder = next(f for f in folders if (f / input_name).is_file())
    monkeypatch.chdir(folder)
    options = read_input_file(input_name, 'dynamic')
    if status == 'runs, GPU':
        assert options.mobility_vector_prod_implementation == 'pycuda'
    else:
        assert status == 'runs', status
    if (folder / 'user_defined_functions.py').is_file():
        hooks = load_hooks(options, str(folder), log=lambda *a: None)
        assert hooks.sources
