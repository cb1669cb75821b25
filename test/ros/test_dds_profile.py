"""The package's Fast DDS profile as our commands' default (ros/dds_profile.py)."""

from infinihand_ros.ros.node_process import use_package_dds_profile


def test_profile_is_set_when_the_user_set_none() -> None:
    """No profile variable: FASTRTPS_DEFAULT_PROFILES_FILE names the shipped XML."""
    environ: dict[str, str] = {}
    profile = use_package_dds_profile(environ)
    assert profile is not None and profile.name == 'fastdds_profile.xml' and profile.is_file()
    assert environ == {'FASTRTPS_DEFAULT_PROFILES_FILE': str(profile)}
    assert '<segment_size>16777216</segment_size>' in profile.read_text()


def test_a_users_profile_or_another_rmw_is_left_alone() -> None:
    """Either profile variable set, or a non-Fast-DDS RMW: nothing changes."""
    for environ in ({'FASTRTPS_DEFAULT_PROFILES_FILE': '/mine.xml'},
                    {'FASTDDS_DEFAULT_PROFILES_FILE': '/mine.xml'},
                    {'RMW_IMPLEMENTATION': 'rmw_cyclonedds_cpp'}):
        before = dict(environ)
        assert use_package_dds_profile(environ) is None
        assert environ == before
    fast = {'RMW_IMPLEMENTATION': 'rmw_fastrtps_dynamic_cpp'}
    assert use_package_dds_profile(fast) is not None
