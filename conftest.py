"""Test-session settings shared by the unit tests and the notebook runs (nbval).

Kernels that nbval starts inherit this process's environment, so setting tqdm's own quiet
switch (TQDM_DISABLE, which ``ibc_tutorial.utils.progress`` honours) here silences progress
bars in the chapters exactly as tools/execute_notebooks.py does when it stores their outputs.
"""

import os

os.environ["TQDM_DISABLE"] = "1"
os.environ.setdefault("MPLBACKEND", "Agg")
