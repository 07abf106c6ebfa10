"""The library's ``index.html`` in a real browser: headless Chromium, driven through its
chromedriver by Selenium, opens the page from disk, and a click on a column header sorts the
table's rows by that column (numbers as numbers, ascending then descending, missing values last).

The index is written from a small hand-made library result (no training): ``report.write_all``
on rows as ``python -m nbrdf_tools library`` stores them. Needs Chromium and its chromedriver
(``make setup`` installs Debian's ``chromium`` and ``chromium-driver`` when run as root); without
them the test is skipped, saying so.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from nbrdf_tools.library import report

# Tone-mapped RMSEs whose text order is not their numeric order ("1e-05" sorts last as text).
RMSE = {"gold": 0.25, "white": 0.0031, "plastic": 0.12, "felt": 1e-05}
EPOCHS = {"gold": 40, "white": 9, "plastic": 120, "felt": 7}


def _row(name: str) -> dict:
    if name not in RMSE:  # a failed conversion: no metrics, no network
        return {"name": name, "status": "failed", "kind": "rgl", "metrics": None, "files": {},
                "training_seconds": None, "epochs": None, "weights": None, "default_sampling": None,
                "wall_seconds": 0.4, "source": f"{name}.bsdf", "error": "train: error: bad header"}
    rmse = RMSE[name]
    return {"name": name, "status": "ok", "kind": "merl",
            "metrics": {"rmse_tonemapped": rmse, "ssim": 1.0 - rmse, "flip_hdr": 2 * rmse,
                        "log_error_adaptive": 3 * rmse, "log_error_uniform": 4 * rmse},
            "files": {"network": f"materials/{name}/{name}.nbrdf.json", "thumbnail": None},
            "training_seconds": 1.5, "epochs": EPOCHS[name], "weights": 675, "default_sampling": "tabulated",
            "wall_seconds": 2.0, "source": f"{name}.binary", "error": None}


def _browser_paths() -> tuple[str, str]:
    """(Chromium, chromedriver), or a skip naming what is missing and how to install it."""
    browser = next(filter(None, map(shutil.which, ("chromium", "chromium-browser", "google-chrome"))), None)
    driver = shutil.which("chromedriver")
    missing = [what for what, path in (("chromium", browser), ("chromedriver", driver)) if path is None]
    if missing:
        pytest.skip(f"no {' or '.join(missing)} on PATH: the library page's browser test needs both "
                    "(make setup installs them as root; Debian: apt-get install chromium chromium-driver)")
    return browser, driver


@pytest.fixture(scope="module")
def browser():
    chromium, chromedriver = _browser_paths()
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for argument in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage"):
        options.add_argument(argument)
    # The driver's path given: Selenium Manager (which would download one) never runs.
    driver = webdriver.Chrome(service=Service(executable_path=chromedriver), options=options)
    try:
        yield driver
    finally:
        driver.quit()


@pytest.fixture(scope="module")
def page(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("library-page")
    names = ["gold", "broken", "white", "plastic", "felt"]
    paths = report.write_all(out, [_row(name) for name in names], {"command": "nbrdf_tools library test"})
    return paths["html"]


def _names_in_order(driver) -> list[str]:
    """The material names of the table's rows, top to bottom, as the page shows them."""
    from selenium.webdriver.common.by import By

    heads = [th.get_attribute("data-column") for th in driver.find_elements(By.CSS_SELECTOR, "#materials thead th")]
    column = heads.index("name")
    return [row.find_elements(By.TAG_NAME, "td")[column].text
            for row in driver.find_elements(By.CSS_SELECTOR, "#materials tbody tr")]


def _click(driver, column: str) -> None:
    from selenium.webdriver.common.by import By

    driver.find_element(By.CSS_SELECTOR, f'#materials th[data-column="{column}"]').click()


def test_a_header_click_sorts_by_its_column(browser, page):
    browser.get(page.as_uri())
    assert _names_in_order(browser) == ["gold", "broken", "white", "plastic", "felt"]  # as written
    by_rmse = sorted(RMSE, key=RMSE.get)
    _click(browser, "rmse_tonemapped")
    assert _names_in_order(browser) == [*by_rmse, "broken"]  # numeric, the failed row (no value) last
    _click(browser, "rmse_tonemapped")
    assert _names_in_order(browser) == [*reversed(by_rmse), "broken"]
    _click(browser, "epochs")  # another column starts ascending again
    assert _names_in_order(browser) == [*sorted(EPOCHS, key=EPOCHS.get), "broken"]
    _click(browser, "name")
    assert _names_in_order(browser) == sorted([*RMSE, "broken"])
    from selenium.webdriver.common.by import By

    arrows = {th.get_attribute("data-column"): th.get_attribute("data-order")
              for th in browser.find_elements(By.CSS_SELECTOR, "#materials th[data-column]")}
    assert {column for column, order in arrows.items() if order} == {"name"} and arrows["name"] == "asc"
