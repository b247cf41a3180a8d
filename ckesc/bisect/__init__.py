"""``ckesc bisect`` (issue #37): the first bad image of a build history, found by running a selection on the
images between a known-good and a known-bad one. :mod:`.core` judges (sans IO), :mod:`.steps` runs each step as a
``ckesc run`` and :mod:`.report` writes what every step said."""
