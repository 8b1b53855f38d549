"""An independent crank-slider: Exudyn's geometrically exact ANCF cable elements (C++ solver,
generalised-α with spectral radius 1), the same data, undeformed start with the rigid
velocities. Test helper only: stillframe does not depend on Exudyn."""

from __future__ import annotations

import warnings

import exudyn as exu
import numpy as np
from exudyn.beams import GenerateStraightLineANCFCable2D
from exudyn.utilities import (
    CoordinateConstraint,
    MarkerNodeCoordinate,
    MassPoint2D,
    NodePoint2D,
    NodePointGround,
    ObjectANCFCable2D,
    SensorNode,
)

from stillframe.dynamics.ph.crank_slider import COUPLER, CRANK, CrankSliderData


def midpoint_deflection(data: CrankSliderData, elements: int, crank_angle_end: float,
                        dt: float = 1e-5, samples: int = 200) -> np.ndarray:
    """Rows (crank angle, w_mid / L): the midpoint's distance from the chord P–C over L."""
    rate = data.crank_rate
    sc = exu.SystemContainer()
    mbs = sc.AddSystem()
    cable = ObjectANCFCable2D(physicsMassPerLength=data.density * data.area,
                              physicsBendingStiffness=data.young * data.second_moment,
                              physicsAxialStiffness=data.young * data.area, nodeNumbers=[0, 0])
    with warnings.catch_warnings():  # deprecated in Exudyn 1.11, kept until 2029
        warnings.simplefilter("ignore", DeprecationWarning)
        nodes = GenerateStraightLineANCFCable2D(
            mbs, positionOfNode0=[CRANK, 0, 0], positionOfNode1=[CRANK + COUPLER, 0, 0],
            numberOfElements=elements, cableTemplate=cable, massProportionalLoad=[0, 0, 0],
            fixedConstraintsNode0=[0, 0, 0, 0], fixedConstraintsNode1=[0, 0, 0, 0])[0]
    ground = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=mbs.AddNode(NodePointGround()),
                                                coordinate=0))
    paths = (lambda mbs, t, i, o: CRANK * np.cos(rate * t) - CRANK,
             lambda mbs, t, i, o: CRANK * np.sin(rate * t))
    for c, path in enumerate(paths):
        marker = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=nodes[0], coordinate=c))
        mbs.AddObject(CoordinateConstraint(markerNumbers=[ground, marker],
                                           offsetUserFunction=path))
    slider = mbs.AddNode(NodePoint2D(referenceCoordinates=[CRANK + COUPLER, 0]))
    mbs.AddObject(MassPoint2D(mass=data.slider_mass, nodeNumber=slider))
    for c in (0, 1):
        end = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=nodes[-1], coordinate=c))
        block = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=slider, coordinate=c))
        mbs.AddObject(CoordinateConstraint(markerNumbers=[end, block]))
    mbs.AddObject(CoordinateConstraint(markerNumbers=[
        ground, mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=slider, coordinate=1))]))
    omega = -CRANK * rate / COUPLER
    for k, node in enumerate(nodes):
        along = COUPLER * k / elements
        mbs.SetNodeParameter(node, "initialVelocities",
                             [0.0, CRANK * rate + omega * along, 0.0, omega])
    sensors = [mbs.AddSensor(SensorNode(nodeNumber=nodes[i], storeInternal=True,
                                        outputVariableType=exu.OutputVariableType.Position))
               for i in (0, elements // 2, elements)]
    mbs.Assemble()
    settings = exu.SimulationSettings()
    t_end = crank_angle_end / rate
    settings.timeIntegration.numberOfSteps = round(t_end / dt)
    settings.timeIntegration.endTime = t_end
    settings.timeIntegration.generalizedAlpha.spectralRadius = 1.0
    settings.timeIntegration.verboseMode = 0
    settings.solution.sensors.writePeriod = t_end / samples
    settings.solution.file.write = False
    mbs.SolveDynamic(settings)
    p, m, c = (mbs.GetSensorStoredData(s) for s in sensors)
    chord = c[:, 1:3] - p[:, 1:3]
    cross = chord[:, 0] * (m[:, 2] - p[:, 2]) - chord[:, 1] * (m[:, 1] - p[:, 1])
    return np.column_stack([rate * p[:, 0], cross / np.linalg.norm(chord, axis=1) / COUPLER])
