//! Contact detection for the tree engine: every collider against the ground and, with self-collision,
//! against the colliders of other bodies (never those moving with it or with its parent through fixed
//! joints).
//! The ground plane is met in closed form (`plane`) by primitives; convex meshes on the plane, a heightfield
//! and body pairs go through parry, each pair keeping its contact manifolds from step to step. Either way a contact point is matched to the
//! last step's by the shapes' features and inherits its impulses (the solver's warm start).

use parry3d_f64::bounding_volume::{Aabb, BoundingVolume};
use parry3d_f64::math::Pose;
use parry3d_f64::query::{ContactManifold, ContactManifoldsWorkspace, DefaultQueryDispatcher, PersistentQueryDispatcher};
use parry3d_f64::shape::SharedShape;

use nalgebra::Vector3;

use super::plane::{plane_points, reach, MAX_FEATURES};
use crate::geometry::{from_vector, to_pose, ShapeKind};
use crate::model::Model;
use crate::sim::options::Options;
use crate::sim::Ground;
use crate::spatial::Transform;

/// Contacts are tracked from this distance apart (m), so an approaching body is slowed before it touches.
pub(super) const PREDICTION: f64 = 1e-3;

/// What a contact point carries from one step to the next: the impulses [λ_n, λ_t (world, 3)].
pub(super) type Warm = [f64; 4];

/// A contact's impulses [λ_n, λ_t1, λ_t2] along its normal and `tangents` as a warm start: λ_n and its friction in the
/// world's axes (what `Collision::store` keeps).
pub(super) fn warm_of(tangents: &[Vector3<f64>; 2], lambda: &[f64; 3]) -> Warm {
    let friction = tangents[0] * lambda[1] + tangents[1] * lambda[2];
    [lambda[0], friction.x, friction.y, friction.z]
}

struct Collider {
    body: usize,
    /// The body of the fused model that `body` moves with, and that body's parent.
    carrier: usize,
    parent_carrier: usize,
    /// It meets the ground through parry (a heightfield, or a convex mesh on the plane), not in closed form.
    parry_ground: bool,
    kind: ShapeKind,
    /// Its points' greatest distance from its frame's origin (`plane::reach`).
    reach: Option<f64>,
    /// Shape frame in the body frame.
    local: Transform,
    shape: SharedShape,
    /// Parry's shape frame in the body frame (parry's cylinder runs along y).
    parry_local: Transform,
}

/// Where a contact point lives, to hand its impulses back.
#[derive(Debug, Clone, Copy)]
pub(super) enum Source {
    /// Feature `1` of collider `0` on the ground plane.
    Plane(u32, u32),
    /// Point `2` of manifold `1` of pair `0` (pairs below the number of colliders are heightfield pairs).
    Manifold(u32, u32, u32),
}

#[derive(Default)]
pub(super) struct Pair {
    pub manifolds: Vec<ContactManifold<(), Warm>>,
    workspace: Option<ContactManifoldsWorkspace>,
}

impl Clone for Pair {
    fn clone(&self) -> Self {
        Pair { manifolds: self.manifolds.clone(), workspace: self.workspace.clone() }
    }

    /// Reuses this pair's buffers: a step saves its pairs every step, which must not allocate once warm
    /// (only a composite shape's workspace, a heightfield's, is copied anew).
    fn clone_from(&mut self, other: &Self) {
        self.manifolds.truncate(other.manifolds.len());
        let kept = self.manifolds.len();
        for (to, from) in self.manifolds.iter_mut().zip(&other.manifolds) {
            let ContactManifold { points, local_n1, local_n2, subshape1, subshape2, subshape_poses, data } = from;
            to.points.clone_from(points);
            (to.local_n1, to.local_n2, to.subshape1, to.subshape2, to.data) = (*local_n1, *local_n2, *subshape1, *subshape2, *data);
            to.subshape_poses.clone_from(subshape_poses);
        }
        self.manifolds.extend_from_slice(&other.manifolds[kept..]);
        self.workspace.clone_from(&other.workspace);
    }
}

/// One contact point of this step, between `body` (pushed along `normal`) and `other` (the ground if None).
#[derive(Debug, Clone, Copy)]
pub(super) struct Found {
    pub body: usize,
    pub other: Option<usize>,
    pub point: Vector3<f64>,
    pub normal: Vector3<f64>,
    /// An orthonormal pair spanning the contact plane: the friction directions.
    pub tangents: [Vector3<f64>; 2],
    /// Signed distance (m): negative when the shapes overlap.
    pub distance: f64,
    pub warm: Warm,
    pub source: Source,
}

/// What a step changed of a `Collision`, to undo it: the plane impulses of the colliders it changed
/// (collider, old impulses, old activity), in order, and parry's pairs as they were.
#[derive(Default)]
pub(super) struct History {
    plane_warm: Vec<(u32, [Warm; MAX_FEATURES], bool)>,
    ground_pairs: Vec<Pair>,
    self_pairs: Vec<(u32, u32, Pair)>,
}

pub(super) struct Collision {
    colliders: Vec<Collider>,
    /// The ground as a parry shape, for the colliders that meet it through parry; None if none does.
    ground: Option<(SharedShape, Pose)>,
    /// The ground plane's frame (plane to world), met in closed form by the primitives; None if no plane.
    plane: Option<Transform>,
    /// Impulses of each collider's features on the plane, from the last step, and whether any may be
    /// non-zero (the collider touched the plane).
    plane_warm: Vec<[Warm; MAX_FEATURES]>,
    plane_active: Vec<bool>,
    ground_pairs: Vec<Pair>,
    self_collision: bool,
    /// Overlapping collider pairs (a < b) of the last step, sorted, with their manifolds.
    self_pairs: Vec<(u32, u32, Pair)>,
    poses: Vec<Pose>,
    boxes: Vec<Aabb>,
    order: Vec<u32>,
    candidates: Vec<(u32, u32)>,
    dispatcher: DefaultQueryDispatcher,
}

impl Collision {
    /// The colliders of `options` on `model`, body i moving with body `fused_body[i]` of `fused` (see
    /// `TreeSimulation`).
    pub(super) fn new(model: &Model, options: &Options, fused: &Model, fused_body: &[usize]) -> Self {
        let plane = match &options.ground {
            Some(Ground::Plane { placement, .. }) => Some(*placement),
            _ => None,
        };
        let colliders: Vec<Collider> = options
            .colliders(model)
            .map(|(i, shape, in_body)| {
                let (shared, correction) = shape.shared_shape();
                let carrier = fused_body[i];
                Collider {
                    body: i,
                    carrier,
                    parent_carrier: if carrier == 0 { 0 } else { fused.parent(carrier) },
                    parry_ground: options.ground.is_some() && (plane.is_none() || matches!(shape.kind, ShapeKind::Convex(_))),
                    reach: reach(&shape.kind),
                    kind: shape.kind,
                    local: in_body,
                    shape: shared,
                    parry_local: in_body.compose(&correction),
                }
            })
            .collect();
        let n = colliders.len();
        Collision {
            ground: options.ground.as_ref().filter(|_| colliders.iter().any(|c| c.parry_ground)).map(|g| g.shape()),
            plane,
            plane_warm: vec![[[0.0; 4]; MAX_FEATURES]; n],
            plane_active: vec![false; n],
            ground_pairs: (0..n).map(|_| Pair::default()).collect(),
            colliders,
            self_collision: options.self_collision,
            self_pairs: Vec::new(),
            poses: vec![Pose::IDENTITY; n],
            boxes: Vec::with_capacity(n),
            order: Vec::with_capacity(n),
            candidates: Vec::new(),
            dispatcher: DefaultQueryDispatcher,
        }
    }

    /// The bodies that carry colliders, in order, each once.
    pub(super) fn bodies(&self) -> Vec<usize> {
        let mut bodies: Vec<usize> = self.colliders.iter().map(|c| c.body).collect();
        bodies.sort_unstable();
        bodies.dedup();
        bodies
    }

    /// Starts recording what the next step changes, so that `undo` can take it back.
    pub(super) fn save(&mut self, history: &mut History) {
        history.plane_warm.clear();
        // Parry's pairs are copied whole (only heightfields, meshes on the plane and self-collision have
        // them); a collider's plane impulses are logged when it touches, which costs nothing per idle one.
        if self.ground.is_some() {
            history.ground_pairs.clone_from(&self.ground_pairs);
        }
        if self.self_collision {
            // Element by element, so that each pair reuses its buffers (a tuple's clone_from would not).
            let saved = &mut history.self_pairs;
            saved.truncate(self.self_pairs.len());
            let kept = saved.len();
            for (to, (a, b, pair)) in saved.iter_mut().zip(&self.self_pairs) {
                (to.0, to.1) = (*a, *b);
                to.2.clone_from(pair);
            }
            saved.extend(self.self_pairs[kept..].iter().cloned());
        }
    }

    /// Returns to the state of the last `save`.
    pub(super) fn undo(&mut self, history: &mut History) {
        for &(collider, warm, active) in history.plane_warm.iter().rev() {
            self.plane_warm[collider as usize] = warm;
            self.plane_active[collider as usize] = active;
        }
        history.plane_warm.clear();
        if self.ground.is_some() {
            std::mem::swap(&mut self.ground_pairs, &mut history.ground_pairs);
        }
        if self.self_collision {
            std::mem::swap(&mut self.self_pairs, &mut history.self_pairs);
        }
    }

    /// Forgets every contact (no warm start for what follows).
    pub(super) fn clear(&mut self) {
        self.ground_pairs.iter_mut().for_each(|p| *p = Pair::default());
        self.plane_warm.iter_mut().for_each(|w| *w = [[0.0; 4]; MAX_FEATURES]);
        self.plane_active.fill(false);
        self.self_pairs.clear();
    }

    /// Finds the contacts of bodies at world poses `poses`, appending them to `out`; the plane impulses of
    /// the colliders it may change go to `history` first.
    pub(super) fn detect(&mut self, poses: &[Transform], out: &mut Vec<Found>, history: &mut History) {
        if let Some(plane) = &self.plane {
            // Each shape is met in the plane's frame, where the plane is z = 0; points go back to the world.
            let (to_plane, normal) = (plane.inverse(), plane.rotation.column(2).into_owned());
            let frame = tangents(&normal);
            for (index, c) in self.colliders.iter().enumerate() {
                // The shape's origin in the plane's frame first, by the products that place its pose below: a
                // shape beyond its reach of the plane (most of a standing robot's) has no point near it
                // (`plane_points`), and one that had none last step either has nothing to find or log.
                let origin = to_plane.transform_point(&poses[c.body].transform_point(&c.local.translation));
                let near = c.reach.is_some_and(|reach| origin.z - reach <= PREDICTION);
                if !near && !self.plane_active[index] {
                    continue;
                }
                let warm = &mut self.plane_warm[index];
                let mut touching = [false; MAX_FEATURES];
                if near {
                    let pose = to_plane.compose(&poses[c.body].compose(&c.local));
                    plane_points(&c.kind, c.reach, &pose, PREDICTION, |p| {
                        touching[p.feature] = true;
                        out.push(Found {
                            body: c.body,
                            other: None,
                            point: plane.transform_point(&Vector3::new(p.surface.x, p.surface.y, 0.5 * p.height)),
                            normal,
                            tangents: frame,
                            distance: p.height,
                            warm: warm[p.feature],
                            source: Source::Plane(index as u32, p.feature as u32),
                        });
                    });
                }
                // Only a collider touching now or last step has impulses to change: it is logged whole.
                let touches = touching.contains(&true);
                if touches || self.plane_active[index] {
                    history.plane_warm.push((index as u32, *warm, self.plane_active[index]));
                    for (w, t) in warm.iter_mut().zip(touching) {
                        if !t {
                            *w = [0.0; 4];
                        }
                    }
                }
                self.plane_active[index] = touches;
            }
        }
        if !(self.self_collision || self.ground.is_some()) {
            return;
        }
        for (pose, c) in self.poses.iter_mut().zip(&self.colliders) {
            *pose = to_pose(&poses[c.body].compose(&c.parry_local));
        }
        if let Some((ground, ground_pose)) = &self.ground {
            for (index, (c, pair)) in self.colliders.iter().zip(self.ground_pairs.iter_mut()).enumerate().filter(|(_, (c, _))| c.parry_ground) {
                let pos12 = ground_pose.inv_mul(&self.poses[index]);
                let found = self.dispatcher.contact_manifolds(
                    &pos12,
                    ground.as_ref(),
                    c.shape.as_ref(),
                    PREDICTION,
                    &mut pair.manifolds,
                    &mut pair.workspace,
                );
                if found.is_err() {
                    pair.manifolds.clear();
                }
                collect(pair, ground_pose, &self.poses[index], c.body, None, index as u32, out);
            }
        }
        if self.self_collision {
            self.detect_self(out);
        }
    }

    fn detect_self(&mut self, out: &mut Vec<Found>) {
        // Sweep and prune along x over bounding boxes grown by the prediction distance.
        self.boxes.clear();
        self.boxes.extend(self.colliders.iter().zip(&self.poses).map(|(c, p)| c.shape.compute_aabb(p).loosened(PREDICTION / 2.0)));
        self.order.clear();
        self.order.extend(0..self.colliders.len() as u32);
        let boxes = &self.boxes;
        self.order.sort_by(|&a, &b| boxes[a as usize].mins.x.total_cmp(&boxes[b as usize].mins.x).then(a.cmp(&b)));
        self.candidates.clear();
        for (n, &a) in self.order.iter().enumerate() {
            for &b in &self.order[n + 1..] {
                if boxes[b as usize].mins.x > boxes[a as usize].maxs.x {
                    break;
                }
                let (ca, cb) = (&self.colliders[a as usize], &self.colliders[b as usize]);
                let related = ca.carrier == cb.carrier
                    || ca.carrier == cb.parent_carrier && cb.carrier != 0
                    || cb.carrier == ca.parent_carrier && ca.carrier != 0;
                if !related && boxes[a as usize].intersects(&boxes[b as usize]) {
                    self.candidates.push((a.min(b), a.max(b)));
                }
            }
        }
        self.candidates.sort_unstable();
        // Keep the manifolds of pairs that still overlap, in the candidates' order.
        let mut previous = std::mem::take(&mut self.self_pairs).into_iter().peekable();
        for &(a, b) in &self.candidates {
            while previous.peek().is_some_and(|(pa, pb, _)| (*pa, *pb) < (a, b)) {
                previous.next();
            }
            let pair = match previous.peek() {
                Some((pa, pb, _)) if (*pa, *pb) == (a, b) => previous.next().expect("peeked").2,
                _ => Pair::default(),
            };
            self.self_pairs.push((a, b, pair));
        }
        let base = self.colliders.len() as u32;
        for (index, (a, b, pair)) in self.self_pairs.iter_mut().enumerate() {
            let (pa, pb) = (&self.poses[*a as usize], &self.poses[*b as usize]);
            let (ca, cb) = (&self.colliders[*a as usize], &self.colliders[*b as usize]);
            let found = self.dispatcher.contact_manifolds(
                &pa.inv_mul(pb),
                ca.shape.as_ref(),
                cb.shape.as_ref(),
                PREDICTION,
                &mut pair.manifolds,
                &mut pair.workspace,
            );
            if found.is_err() {
                pair.manifolds.clear();
            }
            // The normal points from a to b: the force along it acts on b.
            collect(pair, pa, pb, cb.body, Some(ca.body), base + index as u32, out);
        }
    }

    /// Contact `f` of the last detection, its shapes moved to the bodies' world poses `poses`, keeping its
    /// source and warm start: a plane contact is the same feature of its shape, re-evaluated in closed form;
    /// a contact from parry's manifolds keeps its points on their shapes and its normal on the first shape,
    /// parry not re-run, a face's point the other shape's vertex projected onto it: exact for a vertex on a
    /// face or on the ground, first-order in the points' sliding for other features. Used to differentiate a
    /// step's contacts with respect to the configuration (`transition`).
    pub(super) fn moved(&self, f: &Found, poses: &[Transform]) -> Found {
        let mut moved = *f;
        match f.source {
            Source::Plane(index, feature) => {
                let (c, plane) = (&self.colliders[index as usize], self.plane.as_ref().expect("a plane contact has the plane"));
                plane_points(&c.kind, c.reach, &plane.inverse().compose(&poses[c.body].compose(&c.local)), f64::INFINITY, |p| {
                    if p.feature == feature as usize {
                        moved.point = plane.transform_point(&Vector3::new(p.surface.x, p.surface.y, 0.5 * p.height));
                        moved.distance = p.height;
                    }
                });
            }
            Source::Manifold(pair, manifold, point) => {
                let n = self.colliders.len();
                let (pose1, pose2, pair, ground) = match self.ground_pairs.get(pair as usize) {
                    Some(p) => {
                        let c = &self.colliders[pair as usize];
                        (self.ground.as_ref().expect("a ground pair has the ground").1, to_pose(&poses[c.body].compose(&c.parry_local)), p, true)
                    }
                    None => {
                        let (a, b, p) = &self.self_pairs[pair as usize - n];
                        let (ca, cb) = (&self.colliders[*a as usize], &self.colliders[*b as usize]);
                        (to_pose(&poses[ca.body].compose(&ca.parry_local)), to_pose(&poses[cb.body].compose(&cb.parry_local)), p, false)
                    }
                };
                let manifold = &pair.manifolds[manifold as usize];
                let frame1 = manifold.subshape_pos1().map_or(pose1, |s| pose1 * *s);
                let frame2 = manifold.subshape_pos2().map_or(pose2, |s| pose2 * *s);
                let contact = &manifold.points[point as usize];
                let (mut p1, mut p2) = (from_vector(frame1 * contact.local_p1), from_vector(frame2 * contact.local_p2));
                moved.normal = from_vector(frame1.rotation * manifold.local_n1);
                // A face's point is the other shape's vertex projected onto it (the ground's: the body's).
                let gap = (p2 - p1).dot(&moved.normal);
                if ground || contact.fid1.is_face() && contact.fid2.is_vertex() {
                    p1 = p2 - moved.normal * gap;
                } else if contact.fid2.is_face() && contact.fid1.is_vertex() {
                    p2 = p1 + moved.normal * gap;
                }
                moved.tangents = tangents(&moved.normal);
                moved.point = (p1 + p2) * 0.5;
                moved.distance = gap;
            }
        }
        moved
    }

    /// Stores the impulses of the contact at `source` for the next step's warm start (a plane contact's
    /// collider was logged by `detect`, which found it).
    pub(super) fn store(&mut self, source: Source, warm: Warm) {
        match source {
            Source::Plane(collider, feature) => self.plane_warm[collider as usize][feature as usize] = warm,
            Source::Manifold(pair, manifold, point) => {
                let pair = match self.ground_pairs.get_mut(pair as usize) {
                    Some(p) => p,
                    None => &mut self.self_pairs[pair as usize - self.colliders.len()].2,
                };
                pair.manifolds[manifold as usize].points[point as usize].data = warm;
            }
        }
    }
}

/// Appends the points of `pair` (shape 1 at `pose1`, shape 2 at `pose2`), the force along the normal acting
/// on `body` (shape 2's).
fn collect(pair: &Pair, pose1: &Pose, pose2: &Pose, body: usize, other: Option<usize>, index: u32, out: &mut Vec<Found>) {
    for (m, manifold) in pair.manifolds.iter().enumerate() {
        let (sub1, sub2) = (manifold.subshape_pos1(), manifold.subshape_pos2());
        let frame1 = sub1.map_or(*pose1, |s| *pose1 * *s);
        let frame2 = sub2.map_or(*pose2, |s| *pose2 * *s);
        let normal = from_vector(frame1.rotation * manifold.local_n1);
        let frame = tangents(&normal);
        for (p, point) in manifold.points.iter().enumerate() {
            if point.dist > PREDICTION {
                continue;
            }
            // A face's point is the other shape's vertex projected onto it (the ground's: the body's), as
            // `moved` takes it: parry keeps a persistent manifold's points in each shape's frame, so the face's
            // would otherwise lag behind a vertex sliding over it (and the transition Jacobians with it).
            let (mut p1, mut p2) = (from_vector(frame1 * point.local_p1), from_vector(frame2 * point.local_p2));
            let gap = (p2 - p1).dot(&normal);
            if other.is_none() || point.fid1.is_face() && point.fid2.is_vertex() {
                p1 = p2 - normal * gap;
            } else if point.fid2.is_face() && point.fid1.is_vertex() {
                p2 = p1 + normal * gap;
            }
            out.push(Found {
                body,
                other,
                point: (p1 + p2) * 0.5,
                normal,
                tangents: frame,
                distance: point.dist,
                warm: point.data,
                source: Source::Manifold(index, m as u32, p as u32),
            });
        }
    }
}

/// An orthonormal pair spanning the plane normal to the unit `n` (Duff et al.'s branchless basis).
fn tangents(n: &Vector3<f64>) -> [Vector3<f64>; 2] {
    let sign = 1f64.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    let t1 = Vector3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    [t1, n.cross(&t1)]
}
