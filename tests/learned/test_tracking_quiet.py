"""MLflow stays quiet in our code paths: no type-hint warnings from the pyfunc wrapper, no
artifact-download progress bars on stderr."""
import warnings

import mlflow
import numpy as np
import pandas as pd

from identify.models import make_model
from identify.tracking import load_tracked_model, log_fit


def test_log_and_load_without_warnings_or_progress_bars(mlflow_store, short_records, capsys):
    train, test = short_records
    est = make_model("stribeck").fit(train)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run = log_fit(est, train, test, fit_time=0.0, plots=False)
        capsys.readouterr()
        model = load_tracked_model(run.model_uri)
        pyf = mlflow.pyfunc.load_model(run.model_uri)
        pred = np.asarray(pyf.predict(test.frame.drop(columns=["tau"])))
    err = capsys.readouterr().err
    assert "Downloading artifacts" not in err, err
    assert not [w for w in caught if "type hint" in str(w.message).lower()], [str(w.message) for w in caught]
    np.testing.assert_array_equal(pred, model.predict(test))
    assert isinstance(pyf.predict(test.frame), pd.Series)
