"""Launch the estimator (and, with bundle_adjustment:=node, the BA node) with their params files.

    ros2 launch infinihand_ros estimator.launch.py [bundle_adjustment:=none|in_process|node]
        [params_file:=...] [ba_params_file:=...] [namespace:=...] [image:=...]
        [camera_info:=...] [use_sim_time:=true]

For real ROS 2 installs (launch and launch_ros are not among the pip wheels this repository is
tested with; nothing imports this file there). ``bundle_adjustment:=node`` runs BA in the
``bundle_adjustment`` node next to the estimator; ``in_process`` in the estimator's engine;
``none`` (the default, as the node's) not at all: the per-frame camera tracker alone (the values
of the node's ``engine.bundle_adjustment``). Both nodes share
the namespace, so their ``bundle_adjustment/*`` topics meet.
"""

from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import EqualsSubstitution
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

PACKAGE = 'infinihand_ros'
BA_CHOICES = ['none', 'in_process', 'node']


def generate_launch_description() -> LaunchDescription:
    """Return the estimator (and BA node) with their parameters and input remappings."""
    config = Path(get_package_share_directory(PACKAGE)) / 'config'
    arguments = [
        DeclareLaunchArgument('params_file', default_value=str(config / 'estimator.yaml'),
                              description='estimator parameters (config/estimator.yaml layout)'),
        DeclareLaunchArgument('ba_params_file',
                              default_value=str(config / 'bundle_adjustment.yaml'),
                              description='BA node parameters '
                                          '(config/bundle_adjustment.yaml layout)'),
        DeclareLaunchArgument('bundle_adjustment', default_value='none', choices=BA_CHOICES,
                              description='where bundle adjustment runs'),
        DeclareLaunchArgument('namespace', default_value='', description='namespace of both'),
        DeclareLaunchArgument('image', default_value='image', description='image topic'),
        DeclareLaunchArgument('camera_info', default_value='camera_info',
                              description='camera_info topic'),
        DeclareLaunchArgument('use_sim_time', default_value='false',
                              description='use /clock (a replay with --clock)'),
    ]
    mode = LaunchConfiguration('bundle_adjustment')
    sim_time = {'use_sim_time': LaunchConfiguration('use_sim_time')}
    image = LaunchConfiguration('image')
    estimator = Node(
        package=PACKAGE, executable='estimator', name='infinihand_estimator',
        namespace=LaunchConfiguration('namespace'), output='screen',
        parameters=[LaunchConfiguration('params_file'),
                    {'engine.bundle_adjustment': mode}, sim_time],
        remappings=[('image', image), ('image/compressed', [image, '/compressed']),
                    ('camera_info', LaunchConfiguration('camera_info'))])
    bundle_adjustment = Node(
        package=PACKAGE, executable='bundle_adjustment', name='infinihand_bundle_adjustment',
        namespace=LaunchConfiguration('namespace'), output='screen',
        parameters=[LaunchConfiguration('ba_params_file'), sim_time],
        condition=IfCondition(EqualsSubstitution(mode, 'node')))
    return LaunchDescription([*arguments, estimator, bundle_adjustment])
