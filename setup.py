"""Build script of the infinihand_ros ament_python package."""

from glob import glob

from setuptools import find_packages
from setuptools import setup

PACKAGE_NAME = 'infinihand_ros'

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(include=[PACKAGE_NAME, f'{PACKAGE_NAME}.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE_NAME}']),
        (f'share/{PACKAGE_NAME}', ['package.xml']),
        (f'share/{PACKAGE_NAME}/config', glob('config/*.yaml') + glob('config/*.xml')),
        (f'share/{PACKAGE_NAME}/msg_schemas/msg', glob('msg_schemas/msg/*.msg')),
        (f'share/{PACKAGE_NAME}/data', glob('data/*.yaml')),
        (f'share/{PACKAGE_NAME}/data/sample_bag', glob('data/sample_bag/*')),
        *((f'share/{PACKAGE_NAME}/{model}', glob(f'{model}/*')) for model in glob('models/*')),
        (f'share/{PACKAGE_NAME}/launch', glob('launch/*.launch.py')),
    ],
    install_requires=['setuptools'],
    extras_require={'test': ['pytest']},
    zip_safe=True,
    maintainer='infinihand_ros maintainers',
    maintainer_email='maintainers@infinihand-ros.org',
    description='Streaming world-space 3D hands and camera trajectories from egocentric video.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            f'synth = {PACKAGE_NAME}.synth.cli:main',
            f'train = {PACKAGE_NAME}.train.cli:main',
            f'estimator = {PACKAGE_NAME}.ros.estimator.node:main',
            f'replay = {PACKAGE_NAME}.tools.replay:main',
            f'record = {PACKAGE_NAME}.tools.record:main',
            f'bundle_adjustment = {PACKAGE_NAME}.ros.bundle_adjustment.node:main',
            f'bag_to_dataset = {PACKAGE_NAME}.convert.cli:console_main',
            f'build_corpus = {PACKAGE_NAME}.corpus.cli:main',
            f'live_demo = {PACKAGE_NAME}.tools.live_demo:main',
            f'retargeting_stub = {PACKAGE_NAME}.ros.retargeting_stub:main',
        ],
    },
)
