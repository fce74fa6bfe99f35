"""scene.contact.blend_length: the hertz_oriented law's ℓ_blend from the config (docs/contact.md)."""

import pytest

from fiberpipe.config import validate_config
from fiberpipe.errors import ConfigError
from fiberpipe.config import MaterialConfig
from fiberpipe.solver.laws import law_from_config
from fiberpipe.solver.laws import P_LBLEND


def _scene(contact):
    return validate_config({"name": "b", "input": {"fibers": "x.h5"},
                            "scene": {"effects": ["contact"], "contact": contact}}).scene


def test_blend_length_reaches_the_law():
    mat = MaterialConfig(youngs_modulus=15e9, poisson_ratio=0.3, density=1380.0)
    law = law_from_config(_scene({"law": "hertz_oriented", "blend_length": "0.15 mm"}).contact, mat)
    assert law.params()[P_LBLEND] == pytest.approx(0.15e-3)
    default = law_from_config(_scene({"law": "hertz_oriented"}).contact, mat)
    assert default.params()[P_LBLEND] == pytest.approx(5e-5)  # the config schema's default
    # every law with a point part takes it (the patch criterion)
    for c in ({"law": "linear", "stiffness": 1e9}, {"law": "hertz_crossed", "angle": "6 deg"},
              {"law": "scaled_stiffness", "preset": "table1_phi6"}):
        law = law_from_config(_scene(c).contact, mat)
        assert law.params()[P_LBLEND] == pytest.approx(5e-5), c
        law = law_from_config(_scene({**c, "blend_length": "0.15 mm"}).contact, mat)
        assert law.params()[P_LBLEND] == pytest.approx(0.15e-3), c


@pytest.mark.parametrize("contact, msg", [
    ({"law": "hertz_oriented", "blend_length": "-1 mm"}, "blend_length"),
    ({"law": "hertz_parallel", "blend_length": "0.15 mm"}, "no point part"),
    ({"law": "hertz_oriented", "blend_length": "3 kg"}, "blend_length"),
])
def test_blend_length_is_checked(contact, msg):
    with pytest.raises(ConfigError, match=msg):
        _scene(contact)
