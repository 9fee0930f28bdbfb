"""The report's index.html in a real headless Chromium (Debian's chromium + chromedriver, via Selenium).

`make test` installs both (scripts/ensure_chromium.sh). The test checks that the page renders without
console errors, every image loads, the compare control works, the page makes no network request,
and a denoiser named like a script tag shows as text.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from denoisebench.dataset.synthetic import make_synthetic_dataset

EVIL = "<script>alert(1)</script>"


def _chromium_paths():
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    return browser, driver


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("browser")
    data = make_synthetic_dataset(root / "ds", scenes=1, frames=2, height=16, width=16, spp=(1, 4))
    (root / "evil.py").write_text(
        textwrap.dedent(
            f"""
        import numpy as np

        class Evil:
            name = {EVIL!r}
            def denoise(self, frame):
                return np.array(frame.color, dtype=np.float32) * np.float32(0.9)
        """
        )
    )
    out = root / "report"
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "denoisebench.cli",
            "benchmark",
            "--time-size",
            "64x64",
            "--data",
            str(data),
            "--db",
            str(root / "r.sqlite"),
            "--denoisers",
            "cross_bilateral_fast",
            "--denoiser",
            f"{root / 'evil.py'}:Evil",
            "--metrics",
            "relmse",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    assert f"report: {(out / 'index.html').resolve()}" in result.stdout
    return out


def test_report_files_are_self_contained(report):
    html = (report / "index.html").read_text()
    for name in ("report.md", "results.json", "results.csv", "figures/accuracy_time.png", "figures/accuracy_time.svg"):
        assert (report / name).is_file(), name
    # nothing fetched from anywhere: no http(s) URL in a src/href, no external script or style
    assert "src=\"http" not in html and "href=\"http" not in html and "<link" not in html
    assert EVIL not in html and "&lt;script&gt;alert(1)&lt;/script&gt;" in html
    assert EVIL not in (report / "report.md").read_text()


@pytest.fixture(scope="module")
def driver():
    browser, chromedriver = _chromium_paths()
    if not browser or not chromedriver:
        pytest.skip("Chromium or chromedriver is missing (make test installs them: scripts/ensure_chromium.sh)")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = browser
    for flag in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--window-size=1400,2000",
    ):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    # the driver from Debian, never a downloaded one (Selenium Manager is not consulted with a path)
    web = webdriver.Chrome(service=Service(executable_path=chromedriver), options=options)
    yield web
    web.quit()


def test_report_renders_in_chromium(report, driver):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    driver.get((report / "index.html").resolve().as_uri())
    assert driver.execute_script("return document.readyState") == "complete"
    errors = [entry for entry in driver.get_log("browser") if entry["level"] in ("SEVERE", "ERROR")]
    assert errors == [], errors

    # every image decoded (data URIs: a broken one has naturalWidth 0)
    images = driver.execute_script("return Array.from(document.images).map(i => [i.alt, i.complete, i.naturalWidth]);")
    assert len(images) >= 8
    assert all(complete and width > 0 for _, complete, width in images), images
    # no request left the page: only data: resources were loaded
    resources = driver.execute_script("return performance.getEntriesByType('resource').map(r => r.name);")
    assert all(name.startswith("data:") for name in resources), resources

    # the evil name is text, not a script: it reads back literally and no alert opened
    body_text = driver.find_element(By.TAG_NAME, "body").text
    assert EVIL in body_text
    assert driver.execute_script("return document.querySelectorAll('script').length") == 1

    # the compare control: slider, select and flip button change what is shown
    box = driver.find_element(By.CSS_SELECTOR, ".compare")
    top = box.find_element(By.CSS_SELECTOR, ".cmp-top")
    slider = box.find_element(By.CSS_SELECTOR, ".cmp-slider")
    assert box.get_attribute("data-wipe") == "50" and "50%" in top.get_attribute("style")
    driver.execute_script("arguments[0].value = 20; arguments[0].dispatchEvent(new Event('input'));", slider)
    assert box.get_attribute("data-wipe") == "20"
    assert "80%" in top.get_attribute("style")
    box.find_element(By.CSS_SELECTOR, ".cmp-toggle").click()
    assert box.get_attribute("data-wipe") == "100"
    box.find_element(By.CSS_SELECTOR, ".cmp-toggle").click()
    assert box.get_attribute("data-wipe") == "0"

    select = Select(box.find_element(By.CSS_SELECTOR, ".cmp-left"))
    labels = [o.text for o in select.options]
    assert "noisy" in labels and EVIL in labels and "cross_bilateral_fast" in labels
    select.select_by_visible_text("noisy")
    noisy_id = select.first_selected_option.get_attribute("value")
    noisy_src = driver.find_element(By.ID, noisy_id).get_attribute("src")
    assert top.get_attribute("src") == noisy_src
    assert box.find_element(By.CSS_SELECTOR, ".cmp-left-name").text == "noisy"
    select.select_by_visible_text(EVIL)
    assert top.get_attribute("src") != noisy_src
    assert box.find_element(By.CSS_SELECTOR, ".cmp-left-name").text == EVIL

    # clicking the stage moves the wipe to the pointer
    stage = box.find_element(By.CSS_SELECTOR, ".cmp-stage")
    from selenium.webdriver.common.action_chains import ActionChains

    width = stage.size["width"]
    ActionChains(driver).move_to_element_with_offset(stage, -width // 4, 0).click().perform()
    assert 15 <= float(box.get_attribute("data-wipe")) <= 35
    assert [e for e in driver.get_log("browser") if e["level"] in ("SEVERE", "ERROR")] == []
