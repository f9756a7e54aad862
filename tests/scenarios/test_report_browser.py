"""The report in a real browser: headless Chromium (Debian's package) decodes every image of a
real run's report; a broken image is caught. CI (.ci/run) installs Chromium and sets
GRINDTWIN_CI, where a missing browser fails the test instead of skipping it."""

from __future__ import annotations

import os
import re
import shutil

import pytest

from scenarios.output import write_report, write_run
from scenarios.output.browser import CHROMIUM_NAMES, image_check
from scenarios.run import run_scene
from tests.scenarios.test_outputs import CYCLONE_SCENE

if not any(shutil.which(n) for n in CHROMIUM_NAMES) and not os.environ.get("GRINDTWIN_CI"):
    pytest.skip("no Chromium (apt-get install -y chromium); CI installs it", allow_module_level=True)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("browser")
    (tmp / "cyclone.toml").write_text(CYCLONE_SCENE)
    return write_report(write_run(run_scene(tmp / "cyclone.toml", progress=False), tmp / "run"))


def test_every_image_of_the_report_loads_in_chromium(report):
    images = image_check(report)
    tags = re.findall(r"<img ", report.read_text(encoding="utf-8"))
    assert len(images) == len(tags) == 7  # the hydrocyclone run has every plot but the estimator's
    assert all(i["ok"] and i["width"] > 300 and i["height"] > 200 for i in images), images


def test_a_broken_image_is_reported(report, tmp_path):
    text = report.read_text(encoding="utf-8")
    broken = re.sub(r'src="data:image/png;base64,[A-Za-z0-9+/=]{40}', 'src="data:image/png;base64,AAAA', text, count=1)
    assert broken != text
    page = tmp_path / "report.html"
    page.write_text(broken, encoding="utf-8")
    ok = [i["ok"] for i in image_check(page)]
    assert ok.count(False) == 1 and ok[0] is False
