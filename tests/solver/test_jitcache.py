"""The solver's numba cache entries are stamped with the sources of every solver module."""

from fiberpipe.solver import _jitcache, _kernels_integrate as K, contact, contact_effect


def test_solver_kernels_use_the_package_wide_cache_stamp():
    assert _jitcache.INSTALLED
    for fn in (K.advance_plain, contact.contact_forces, contact_effect.contact_step):
        loc = fn._cache._impl._locator
        assert type(loc).__name__ == "SolverPackageLocator"
        assert loc.get_source_stamp()[1] == _jitcache.package_source_digest()


def test_step_loop_specialisations():
    assert K.step_loop_for(K.no_contact) is K.advance_plain
    loop = K.step_loop_for(contact_effect.contact_step)
    assert loop is K.step_loop_for(contact_effect.contact_step)
    assert loop._cache._impl is not None  # the built-in contact loop is cached on disk
