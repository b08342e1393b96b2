"""``make demo`` runs on an exported ROS_DOMAIN_ID (labs assign each seat a domain) and says which
domain and why; unset, it reserves a free one (issue 33)."""
import pytest

from biped_sim.cli import demo


def test_an_exported_ros_domain_id_is_the_demos_domain():
    with demo._domain({"ROS_DOMAIN_ID": "42"}) as (dom, source):
        assert (dom, source) == (42, "ROS_DOMAIN_ID")


def test_without_ros_domain_id_the_demo_takes_another_and_says_so():
    with demo._domain({}) as (dom, source):
        assert 0 <= dom <= demo.MAX_DOMAIN_ID and "ROS_DOMAIN_ID unset" in source


@pytest.mark.parametrize("value", ["lab3", "-1", "300"])
def test_a_ros_domain_id_that_is_no_domain_is_one_error(value):
    with pytest.raises(ValueError, match="ROS_DOMAIN_ID"):
        with demo._domain({"ROS_DOMAIN_ID": value}):
            pass
