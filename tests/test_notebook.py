"""notebooks/explore.ipynb runs top to bottom (small settings)."""

from pathlib import Path

from tests.extras import require

require('anny')
nbformat = require('nbformat')
nbclient = require('nbclient')

ROOT = Path(__file__).resolve().parents[1]


def test_explore_notebook_executes(monkeypatch):
    monkeypatch.setenv('SWINGAR_NOTEBOOK_SMALL', '1')
    monkeypatch.setenv('OMP_NUM_THREADS', '1')
    notebook = nbformat.read(ROOT / 'notebooks' / 'explore.ipynb', as_version=4)
    client = nbclient.NotebookClient(notebook, timeout=600, kernel_name='python3',
                                     resources={'metadata': {'path': str(ROOT)}})
    client.execute()
    outputs = [o for cell in notebook.cells if cell.cell_type == 'code' for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == 'error']
    text = ''.join(o.get('text', '') for o in outputs if o.output_type == 'stream')
    # the frequency claim of the layer shows in its output: more alpha, more high frequency
    gains = [float(line.rsplit(' ', 1)[1]) for line in text.splitlines()
             if 'highest quarter of frequencies' in line]
    assert len(gains) == 4 and all(a < b for a, b in zip(gains, gains[1:]))
    assert 'skinning (E, P, LBS)' in text
    images = [o for o in outputs if o.output_type == 'display_data' and 'image/png' in o.data]
    assert len(images) >= 4
