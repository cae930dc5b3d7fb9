# Copyright 2026 The mv3dpose_ros Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
The processes of a rig: one pose2d_node per camera, fusion_node, and the live web view.

One list, read from one rig and one parameter set, which ``mv3dpose_bringup`` starts as child
processes and ``launch/mv3dpose.launch.py`` turns into launch_ros ``Node`` actions, so the two
start the same nodes with the same names, remappings and parameters. Each process's own
parameters go after the params files (a node-specific key of a params file, ``/**/fusion_node``,
wins over ``-p``, so bringup writes them to a file passed last; launch_ros does the same with a
dict); ``RigProcesses.common`` (``use_sim_time``) applies to every node.

Names: ``{camera}`` in the namespace and image topic patterns is the camera's ROS name
(``ros/names.py``: ``00_03`` -> ``cam00_03``); both are checked here, before anything starts.
Nothing here imports rclpy: a dry run and a launch file's evaluation stay light.
"""

from dataclasses import dataclass, field
import os
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

from mv3dpose_ros.core.geometry.calibration import load_calibration
from mv3dpose_ros.io.params_file import node_parameters, ParamsFileError, read_params_file
from mv3dpose_ros.ros.names import camera_topic, check_pattern, RosNameError
from mv3dpose_ros.ros.params import package_search_dirs, resolve_path
import yaml

PACKAGE = 'mv3dpose_ros'
DEFAULT_PARAMS = ('config/pose2d.yaml', 'config/fusion.yaml')
DEFAULT_NAMESPACE = '/{camera}'
DEFAULT_IMAGE_TOPIC = '/{camera}/image_raw'
#: How ``mv3dpose_bringup`` names the inputs in its messages; the launch file passes its own.
BRINGUP_LABELS = {'rig': '--rig', 'namespace': '--namespace', 'image_topic': '--image-topic'}


class PlanError(ValueError):
    """A rig, camera, file or name pattern that no process can start from."""


@dataclass(frozen=True)
class ProcessSpec:
    """One node process: what runs, under which name, with which remappings and parameters."""

    name: str                          #: the process's name in bringup's lines
    node: str                          #: the ROS node name
    executable: str                    #: the console script (setup.py)
    module: str                        #: what ``python -m`` runs where the script is not installed
    namespace: str = ''                #: '' is the root namespace
    remaps: Tuple[Tuple[str, str], ...] = ()
    parameters: Dict[str, Any] = field(default_factory=dict)   #: dotted names -> values

    @property
    def params_key(self) -> str:
        """Return the key of this node's section in a params file."""
        if self.namespace:
            return f'{self.namespace.rstrip("/")}/{self.node}'
        return f'/**/{self.node}'

    def ros_args(self, params_files: Sequence[str]) -> List[str]:
        """Return the ``--ros-args`` part of its command line, the params files last."""
        out = ['--ros-args']
        if self.namespace:
            out += ['-r', f'__ns:={self.namespace}']
        for old, new in self.remaps:
            out += ['-r', f'{old}:={new}']
        for path in params_files:
            out += ['--params-file', path]
        return out

    def launch_kwargs(self, params_files: Sequence[str],
                      common: Mapping[str, Any]) -> Dict[str, Any]:
        """Return the keyword arguments of its launch_ros ``Node``."""
        out = {'package': PACKAGE, 'executable': self.executable, 'name': self.node,
               'output': 'screen', 'remappings': list(self.remaps),
               'parameters': [*params_files, nest({**self.parameters, **common})]}
        if self.namespace:
            out['namespace'] = self.namespace
        return out


@dataclass
class RigProcesses:
    """The processes of one rig, and what they share: the rig, its cameras, the params files."""

    rig_path: str
    cameras: List[str]
    params_files: List[str]
    processes: List[ProcessSpec]
    common: Dict[str, Any] = field(default_factory=dict)   #: parameters of every node

    def overrides(self) -> Dict[str, Any]:
        """Return the params file, passed after the others, of every process's own parameters."""
        out = {p.params_key: {'ros__parameters': nest(p.parameters)} for p in self.processes}
        if self.common:
            out['/**'] = {'ros__parameters': dict(self.common)}
        return out


def nest(flat: Mapping[str, Any]) -> Dict[str, Any]:
    """Turn dotted names into the nested mapping params files use."""
    out: Dict[str, Any] = {}
    for key, value in flat.items():
        node = out
        parts = key.split('.')
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = value
    return out


def parse_assignments(items: Sequence[str], what: str) -> Dict[str, Any]:
    """Return ``{name: value}`` of ``name:=value`` items (values read as YAML, as ``-p`` does)."""
    out = {}
    for item in items:
        if ':=' not in item:
            raise PlanError(f'{what} {item!r} must look like name:=value')
        key, raw = item.split(':=', 1)
        out[key.strip()] = yaml.safe_load(raw) if raw.strip() else ''
    return out


def split_threads(cameras: int, cores: Optional[int] = None) -> int:
    """
    Return onnxruntime intra-op threads per pose2d_node: the cores shared among the cameras.

    Each camera's node gets cores // cameras (at least 1), so N nodes do not start N x cores
    threads that fight over the same cores. Measured in docs/models.md.
    """
    if cores is None:
        try:
            cores = len(os.sched_getaffinity(0))
        except AttributeError:
            cores = os.cpu_count() or 1
    return max(1, int(cores) // max(1, int(cameras)))


def rig_processes(params_files: Sequence[str] = DEFAULT_PARAMS, rig: Optional[str] = None,
                  cameras: Optional[Sequence[str]] = None, namespace: str = DEFAULT_NAMESPACE,
                  image_topic: str = DEFAULT_IMAGE_TOPIC,
                  pose2d_params: Optional[Mapping[str, Any]] = None,
                  fusion_params: Optional[Mapping[str, Any]] = None, pose2d: bool = True,
                  fusion: bool = True, foxglove_port: Optional[int] = None,
                  use_sim_time: bool = False,
                  labels: Mapping[str, str] = BRINGUP_LABELS) -> RigProcesses:
    """
    Return the processes of a rig; ``PlanError`` says why there are none.

    The rig is ``rig``, else fusion_node's ``rig_config`` of the overrides or the params files;
    the cameras are ``cameras``, else its ``camera_ids``, else every camera of the rig.
    ``pose2d_params`` and ``fusion_params`` are dotted names -> values for those nodes; a
    pose2d ``model.threads`` that neither they nor the files set (0) becomes the machine's cores
    shared among the cameras (``split_threads``). Relative paths are found from the working
    directory, then the source tree and the installed share directory.
    """
    search = [os.getcwd()] + package_search_dirs()
    files = [os.path.abspath(resolve_path(p, search)) for p in params_files]
    for path in files:
        if not os.path.isfile(path):
            raise PlanError(f'params file {path!r} not found')
    try:
        docs = [read_params_file(path) or {} for path in files]
    except ParamsFileError as exc:
        raise PlanError(str(exc)) from exc
    fusion_file = node_parameters(docs, 'fusion_node')
    fusion_over = dict(fusion_params or {})
    rig = rig or fusion_over.get('rig_config') or fusion_file.get('rig_config')
    if not rig:
        raise PlanError(f'no rig: pass {labels["rig"]} or set fusion_node rig_config')
    rig_path = os.path.abspath(resolve_path(rig, search))
    try:
        rig_cameras = list(load_calibration(rig_path))
    except (OSError, ValueError) as exc:
        raise PlanError(f'cannot load rig {rig_path!r}: {exc}') from exc
    cams = list(cameras or fusion_over.get('camera_ids') or fusion_file.get('camera_ids') or
                rig_cameras)
    unknown = [c for c in cams if c not in rig_cameras]
    if unknown:
        raise PlanError(f'cameras {unknown} are not in {rig_path} ({", ".join(rig_cameras)})')
    persons = namespace.rstrip('/') + '/persons_2d'
    try:
        check_pattern(namespace, cams, labels['namespace'])
        check_pattern(persons, cams, labels['namespace'])
        if pose2d:
            check_pattern(image_topic, cams, labels['image_topic'])
    except RosNameError as exc:
        raise PlanError(str(exc)) from exc
    out: List[ProcessSpec] = []
    if pose2d:
        own = dict(pose2d_params or {})
        threads = own.get('model.threads', (node_parameters(docs, 'pose2d_node').get('model')
                                            or {}).get('threads', 0))
        if not threads:        # 0 = unset: share the cores instead of N x all cores
            own['model.threads'] = split_threads(len(cams))
        out += [ProcessSpec(f'pose2d_node[{cam}]', 'pose2d_node', 'pose2d_node',
                            'mv3dpose_ros.nodes.pose2d.node', camera_topic(namespace, cam),
                            (('image', camera_topic(image_topic, cam)),),
                            {**own, 'camera_id': cam}) for cam in cams]
    if fusion:
        out.append(ProcessSpec('fusion_node', 'fusion_node', 'fusion_node',
                               'mv3dpose_ros.nodes.fusion.node', parameters={
                                   **fusion_over, 'rig_config': rig_path, 'camera_ids': cams,
                                   'input_topic': persons}))
    if foxglove_port is not None:
        out.append(ProcessSpec('foxglove_view', 'foxglove_view', 'mv3dpose_foxglove_view',
                               'mv3dpose_ros.nodes.foxglove_view', parameters={
                                   'rig_config': rig_path, 'camera_ids': list(cams),
                                   'port': foxglove_port, 'detections_topic': persons}))
    return RigProcesses(rig_path, cams, files, out,
                        {'use_sim_time': True} if use_sim_time else {})
