//! One agent per module on a synchronous bus: Algorithms 1 and 2 (mass properties beyond each connector),
//! the randomised leader election among the grounded modules, and the flooding of the leader's world pose and
//! support line (the docstring of `legkit.agents.network` gives the algorithms; this follows it step by step).
//!
//! A connector is addressed by its link number `6 n + slot`. A channel keeps, per link, the last payload sent
//! and whether it is on the wire: on a synchronous bus a link carries at most one message per round, the
//! payload last sent.

use nalgebra::{Matrix3, Vector3};

use super::{add, inverse, transform, Moments, SLOTS};
use crate::{Error, Result};

const POSE: usize = 19; // connector rotation (9, row-major), position (3), support point (3), direction (3), leader

/// What every module shares: its parts' mass properties and its connectors' frames at zero joint angles
/// (module frame), and its joints.
#[derive(Clone, Debug)]
pub struct ModuleSpec {
    /// Packed moments of block A, link 1, link 2 and block B.
    pub part_moments: [Moments; 4],
    /// Connector frames: rotation and origin (slots 0–2 move with part 0, 3–5 with part 3).
    pub connector_rotation: [Matrix3<f64>; SLOTS],
    /// Connector origins (m), with `connector_rotation`.
    pub connector_position: [Vector3<f64>; SLOTS],
    /// Joint k turns part k + 1 about coordinate axis `joint_axes[k]` through the point (0, 0, `joint_z[k]`).
    pub joint_axes: [usize; 3],
    /// Heights (m) of the joints' axes in the module frame (see `joint_axes`).
    pub joint_z: [f64; 3],
}

/// A module touching the ground: its `block` (0: A, 1: B) has world pose (rotation, translation); the support
/// line through `line_point` along the unit `line_direction`; its election `priority` (distinct per contact).
#[derive(Clone, Debug)]
pub struct GroundContact {
    /// The module that touches.
    pub module: usize,
    /// Its block on the ground: 0 for A, 1 for B.
    pub block: usize,
    /// The block's world rotation.
    pub rotation: Matrix3<f64>,
    /// The block's world position (m).
    pub translation: Vector3<f64>,
    /// A point of the support line (world, m).
    pub line_point: Vector3<f64>,
    /// The support line's unit direction (world).
    pub line_direction: Vector3<f64>,
    /// Election priority: the contact with the highest leads (distinct per contact).
    pub priority: f64,
}

/// One kind of payload on every link (see the module docs).
#[derive(Clone, Debug)]
struct Channel<const W: usize> {
    last_sent: Vec<[f64; W]>,
    has_sent: Vec<bool>,
    on_wire: Vec<bool>,
    sent_by_module: Vec<u64>,
}

impl<const W: usize> Channel<W> {
    fn new(links: usize) -> Self {
        Channel {
            last_sent: vec![[0.0; W]; links],
            has_sent: vec![false; links],
            on_wire: vec![false; links],
            sent_by_module: vec![0; links / SLOTS],
        }
    }

    /// Sends `payload` on `link` where it differs (`!=`) from the last payload sent there.
    fn send_changed(&mut self, link: usize, payload: &[f64; W]) {
        if self.has_sent[link] && self.last_sent[link] == *payload {
            return;
        }
        self.last_sent[link] = *payload;
        self.has_sent[link] = true;
        self.on_wire[link] = true;
        self.sent_by_module[link / SLOTS] += 1;
    }

    /// Takes the message on `link` off the wire, if there is one.
    fn deliver(&mut self, link: usize) -> Option<[f64; W]> {
        std::mem::take(&mut self.on_wire[link]).then(|| self.last_sent[link])
    }

    fn idle(&self) -> bool {
        !self.on_wire.contains(&true)
    }
}

/// The agents of one or more module trees and their synchronous bus.
#[derive(Clone, Debug)]
pub struct Network {
    spec: ModuleSpec,
    /// Per link: the mated link, and the rotation of the partner's connector frame in this one's.
    partner: Vec<Option<usize>>,
    mate: Vec<Matrix3<f64>>,
    ground: Vec<GroundContact>,
    contact_of: Vec<Option<usize>>,
    // What each agent senses: joint angles, its parts' poses and moments, its own moments, connector frames.
    angles: Vec<[f64; 3]>,
    part_rotation: Vec<[Matrix3<f64>; 4]>,
    part_translation: Vec<[Vector3<f64>; 4]>,
    part_moments: Vec<[Moments; 4]>,
    own: Vec<Moments>,
    connector_rotation: Vec<Matrix3<f64>>,
    connector_position: Vec<Vector3<f64>>,
    // Algorithms 1–2: the estimate beyond each connector in its frame, and Algorithm 2's module-frame copy.
    estimate: Vec<Moments>,
    module_estimate: Vec<Moments>,
    // Election and pose.
    leader_key: Vec<f64>,
    leader: Vec<i64>,
    uplink: Vec<Option<usize>>,
    line: Vec<[f64; 6]>,
    pose: Vec<[f64; POSE]>,
    pose_known: Vec<bool>,
    dirty_mass: Vec<bool>,
    dirty_estimate: Vec<bool>,
    dirty_election: Vec<bool>,
    dirty_pose: Vec<bool>,
    mass_channel: Channel<13>,
    election_channel: Channel<2>,
    pose_channel: Channel<POSE>,
}

impl Network {
    /// Agents for `partner` (per link: the mated link or None) with `mate` rotations, grounded by `ground`,
    /// sensing `angles` at start; each runs Algorithm 2 once (round 0).
    pub fn new(
        spec: ModuleSpec, partner: Vec<Option<usize>>, mate: Vec<Matrix3<f64>>, ground: Vec<GroundContact>, angles: &[[f64; 3]],
    ) -> Result<Network> {
        let links = partner.len();
        let n = links / SLOTS;
        if !links.is_multiple_of(SLOTS) || mate.len() != links {
            return Err(Error::invalid("partner", format!("need {SLOTS} connectors per module and one mate rotation each")));
        }
        if partner.iter().enumerate().any(|(l, p)| p.is_some_and(|p| p >= links || partner[p] != Some(l))) {
            return Err(Error::invalid("partner", "every connection must be mutual and within the network"));
        }
        let mut contact_of = vec![None; n];
        for (c, contact) in ground.iter().enumerate() {
            if contact.module >= n || contact.block > 1 || contact_of[contact.module].replace(c).is_some() {
                return Err(Error::invalid("ground", format!("contact {c}: module out of range, block not 0 or 1, or module listed twice")));
            }
        }
        let mut network = Network {
            spec,
            partner,
            mate,
            contact_of,
            angles: vec![[0.0; 3]; n],
            part_rotation: vec![[Matrix3::identity(); 4]; n],
            part_translation: vec![[Vector3::zeros(); 4]; n],
            part_moments: vec![[[0.0; 13]; 4]; n],
            own: vec![[0.0; 13]; n],
            connector_rotation: vec![Matrix3::identity(); links],
            connector_position: vec![Vector3::zeros(); links],
            estimate: vec![[0.0; 13]; links],
            module_estimate: vec![[0.0; 13]; links],
            leader_key: vec![-1.0; n],
            leader: vec![-1; n],
            uplink: vec![None; n],
            line: vec![[0.0; 6]; n],
            pose: vec![Self::no_pose(); links],
            pose_known: vec![false; n],
            dirty_mass: vec![true; n],
            dirty_estimate: vec![true; links],
            dirty_election: vec![true; n],
            dirty_pose: vec![true; n],
            mass_channel: Channel::new(links),
            election_channel: Channel::new(links),
            pose_channel: Channel::new(links),
            ground,
        };
        for contact in &network.ground {
            let m = contact.module;
            network.leader_key[m] = contact.priority;
            network.leader[m] = m as i64;
            network.line[m][..3].copy_from_slice(contact.line_point.as_slice());
            network.line[m][3..].copy_from_slice(contact.line_direction.as_slice());
        }
        check_angles(angles, n)?;
        for (m, &a) in angles.iter().enumerate() {
            network.sense(m, a);
        }
        network.send();
        Ok(network)
    }

    fn no_pose() -> [f64; POSE] {
        let mut pose = [0.0; POSE];
        pose[POSE - 1] = -1.0;
        pose
    }

    /// Number of modules (agents).
    pub fn n_modules(&self) -> usize {
        self.angles.len()
    }

    /// Every agent reads its three joint angles; those whose angles changed recompute their own mass
    /// properties and connector frames and will run Algorithm 2 in the next round.
    pub fn observe(&mut self, angles: &[[f64; 3]]) -> Result<()> {
        check_angles(angles, self.n_modules())?;
        for (m, &a) in angles.iter().enumerate() {
            if a != self.angles[m] {
                self.sense(m, a);
            }
        }
        Ok(())
    }

    /// Module kinematics (`legkit.robots.superbot.module_kinematics`): part k + 1 is part k turned by joint k
    /// about its point p_k, R_{k+1} = R_k J_k and t_{k+1} = t_k + (R_k - R_{k+1}) p_k.
    fn sense(&mut self, m: usize, angles: [f64; 3]) {
        let spec = &self.spec;
        self.angles[m] = angles;
        let (rotation, translation) = (&mut self.part_rotation[m], &mut self.part_translation[m]);
        for k in 0..3 {
            rotation[k + 1] = rotation[k] * axis_rotation(spec.joint_axes[k], angles[k]);
            translation[k + 1] = translation[k] + (rotation[k] - rotation[k + 1]).column(2) * spec.joint_z[k];
        }
        let mut own = spec.part_moments[0];
        self.part_moments[m][0] = spec.part_moments[0];
        for k in 1..4 {
            self.part_moments[m][k] = transform(&rotation[k], &translation[k], &spec.part_moments[k]);
            add(&mut own, &self.part_moments[m][k]);
        }
        self.own[m] = own;
        for slot in 0..SLOTS {
            let l = SLOTS * m + slot;
            let (r, t) = if slot < 3 { (Matrix3::identity(), Vector3::zeros()) } else { (rotation[3], translation[3]) };
            self.connector_rotation[l] = r * spec.connector_rotation[slot];
            self.connector_position[l] = t + r * spec.connector_position[slot];
            self.dirty_estimate[l] = true;
        }
        self.dirty_mass[m] = true;
        self.dirty_pose[m] = true;
    }

    /// One tick: deliver the messages sent in the previous round (Algorithm 1 for each), then Algorithm 2 and
    /// the election and pose updates for every agent that has work.
    pub fn round(&mut self) {
        self.receive();
        self.send();
    }

    /// No agent has work pending and nothing is on the wire.
    pub fn quiescent(&self) -> bool {
        let pending = |flags: &[bool]| flags.contains(&true);
        !(pending(&self.dirty_mass) || pending(&self.dirty_election) || pending(&self.dirty_pose))
            && self.mass_channel.idle()
            && self.election_channel.idle()
            && self.pose_channel.idle()
    }

    /// Data messages sent by each module so far, all channels.
    pub fn sent_by_module(&self) -> impl Iterator<Item = u64> + '_ {
        let (a, b, c) = (&self.mass_channel.sent_by_module, &self.election_channel.sent_by_module, &self.pose_channel.sent_by_module);
        (0..self.n_modules()).map(move |m| a[m] + b[m] + c[m])
    }

    fn receive(&mut self) {
        // Algorithm 1: into the receiving connector's frame (mated connectors share their origin).
        for sender in 0..self.partner.len() {
            let Some(l) = self.partner[sender] else { continue };
            if let Some(payload) = self.mass_channel.deliver(sender) {
                let received = transform(&self.mate[l], &Vector3::zeros(), &payload);
                if received != self.estimate[l] {
                    self.estimate[l] = received;
                    self.dirty_mass[l / SLOTS] = true;
                    self.dirty_estimate[l] = true;
                }
            }
            if let Some([key, leader]) = self.election_channel.deliver(sender) {
                let m = l / SLOTS;
                if key > self.leader_key[m] {
                    self.leader_key[m] = key;
                    self.leader[m] = leader as i64;
                    self.uplink[m] = Some(l % SLOTS);
                    self.dirty_election[m] = true;
                    self.dirty_pose[m] = true;
                }
            }
        }
        // Poses are kept per connector; an agent uses the one on its uplink, if it comes from its leader.
        for sender in 0..self.partner.len() {
            let Some(l) = self.partner[sender] else { continue };
            if let Some(mut payload) = self.pose_channel.deliver(sender) {
                let turned = Matrix3::from_row_slice(&payload[..9]) * self.mate[l];
                for (i, entry) in payload[..9].iter_mut().enumerate() {
                    *entry = turned[(i / 3, i % 3)];
                }
                self.pose[l] = payload;
                let m = l / SLOTS;
                if self.uplink[m] == Some(l % SLOTS) {
                    self.dirty_pose[m] = true;
                }
            }
        }
        for m in 0..self.n_modules() {
            let Some(slot) = self.uplink[m] else {
                self.pose_known[m] = false;
                continue;
            };
            let pose = &self.pose[SLOTS * m + slot];
            self.pose_known[m] = pose[POSE - 1] == self.leader[m] as f64;
            if !self.is_leader(m) {
                self.line[m].copy_from_slice(&pose[12..18]);
            }
        }
    }

    fn send(&mut self) {
        for l in 0..self.partner.len() {
            if std::mem::take(&mut self.dirty_estimate[l]) {
                self.module_estimate[l] = transform(&self.connector_rotation[l], &self.connector_position[l], &self.estimate[l]);
            }
        }
        for m in 0..self.n_modules() {
            // Algorithm 2: T minus what came from connector i, as own + (prefix + suffix) over the other
            // connectors, which never subtracts: the value sent is bit for bit the same whenever its inputs are.
            if std::mem::take(&mut self.dirty_mass[m]) {
                for slot in 0..SLOTS {
                    if !self.connected(m, slot) {
                        continue;
                    }
                    let mut prefix = [0.0; 13];
                    let mut suffix = [0.0; 13];
                    (0..slot).for_each(|other| add(&mut prefix, &self.module_estimate[SLOTS * m + other]));
                    (slot + 1..SLOTS).rev().for_each(|other| add(&mut suffix, &self.module_estimate[SLOTS * m + other]));
                    add(&mut prefix, &suffix);
                    let mut outgoing = self.own[m];
                    add(&mut outgoing, &prefix);
                    let l = SLOTS * m + slot;
                    let (r, t) = inverse(&self.connector_rotation[l], &self.connector_position[l]);
                    self.mass_channel.send_changed(l, &transform(&r, &t, &outgoing));
                }
            }
            // Flooding: the best leader heard of, on every connector but the one it came from.
            if std::mem::take(&mut self.dirty_election[m]) && self.leader_key[m] >= 0.0 {
                for slot in 0..SLOTS {
                    if !self.forwards(m, slot) {
                        continue;
                    }
                    self.election_channel.send_changed(SLOTS * m + slot, &[self.leader_key[m], self.leader[m] as f64]);
                }
            }
            if std::mem::take(&mut self.dirty_pose[m]) && (self.pose_known[m] || self.is_leader(m)) {
                let (rotation, translation) = self.world_pose(m);
                for slot in 0..SLOTS {
                    if !self.forwards(m, slot) {
                        continue;
                    }
                    let l = SLOTS * m + slot;
                    let mut payload = [0.0; POSE];
                    let frame = rotation * self.connector_rotation[l];
                    for (i, entry) in payload[..9].iter_mut().enumerate() {
                        *entry = frame[(i / 3, i % 3)];
                    }
                    payload[9..12].copy_from_slice((translation + rotation * self.connector_position[l]).as_slice());
                    payload[12..18].copy_from_slice(&self.line[m]);
                    payload[18] = self.leader[m] as f64;
                    self.pose_channel.send_changed(l, &payload);
                }
            }
        }
    }

    fn connected(&self, m: usize, slot: usize) -> bool {
        self.partner[SLOTS * m + slot].is_some()
    }

    /// Connected and not the uplink: where an agent forwards what it heard from the leader's side.
    fn forwards(&self, m: usize, slot: usize) -> bool {
        self.connected(m, slot) && Some(slot) != self.uplink[m]
    }

    pub(crate) fn is_leader(&self, m: usize) -> bool {
        self.leader[m] == m as i64
    }

    /// The agent's belief of its module frame's world pose: a leader's from its ground contact, a follower's
    /// from the pose received on its uplink composed with that connector's current frame; identity where no
    /// pose is known.
    pub fn world_pose(&self, m: usize) -> (Matrix3<f64>, Vector3<f64>) {
        if self.is_leader(m) {
            let contact = &self.ground[self.contact_of[m].expect("a leader is a ground module")];
            if contact.block == 0 {
                return (contact.rotation, contact.translation);
            }
            // Standing on block B: the block's pose composed with the inverse of part 3's.
            let (r, t) = inverse(&self.part_rotation[m][3], &self.part_translation[m][3]);
            return (contact.rotation * r, contact.translation + contact.rotation * t);
        }
        match self.uplink[m] {
            Some(slot) if self.pose_known[m] => {
                let l = SLOTS * m + slot;
                let pose = &self.pose[l];
                let received = Matrix3::from_row_slice(&pose[..9]);
                let (r, t) = inverse(&self.connector_rotation[l], &self.connector_position[l]);
                (received * r, received * t + Vector3::new(pose[9], pose[10], pose[11]))
            }
            _ => (Matrix3::identity(), Vector3::zeros()),
        }
    }

    /// The block (0: A, 1: B) on the leader's side of the module: the grounded block for a leader, the uplink
    /// connector's block otherwise; None where no leader is known.
    pub(crate) fn fixed_block(&self, m: usize) -> Option<usize> {
        if self.is_leader(m) {
            return self.contact_of[m].map(|c| self.ground[c].block);
        }
        self.uplink[m].map(|slot| slot / 3)
    }

    /// Module `m`'s joint angles (rad) as last observed.
    pub fn angles(&self, m: usize) -> [f64; 3] {
        self.angles[m]
    }

    pub(crate) fn part_pose(&self, m: usize, part: usize) -> (&Matrix3<f64>, &Vector3<f64>) {
        (&self.part_rotation[m][part], &self.part_translation[m][part])
    }

    pub(crate) fn part_moments(&self, m: usize) -> &[Moments; 4] {
        &self.part_moments[m]
    }

    /// Connector `slot`'s frame in the module frame, at the current joint angles.
    pub fn connector_frame(&self, m: usize, slot: usize) -> (&Matrix3<f64>, &Vector3<f64>) {
        (&self.connector_rotation[SLOTS * m + slot], &self.connector_position[SLOTS * m + slot])
    }

    /// Module `m`'s own moments (its four parts), module frame, at the last observed angles.
    pub fn own(&self, m: usize) -> &Moments {
        &self.own[m]
    }

    /// Algorithm 2's copy of the estimate beyond connector `slot`, module frame (zeros on a free connector).
    pub fn estimate(&self, m: usize, slot: usize) -> &Moments {
        &self.module_estimate[SLOTS * m + slot]
    }

    /// The support line as the agent knows it: point and unit direction.
    pub(crate) fn line(&self, m: usize) -> (Vector3<f64>, Vector3<f64>) {
        let line = &self.line[m];
        (Vector3::new(line[0], line[1], line[2]), Vector3::new(line[3], line[4], line[5]))
    }

    pub(crate) fn spec(&self) -> &ModuleSpec {
        &self.spec
    }
}

fn check_angles(angles: &[[f64; 3]], n: usize) -> Result<()> {
    if angles.len() != n {
        return Err(Error::invalid("angles", format!("need ({n}, 3) joint angles, got {} rows", angles.len())));
    }
    match angles.iter().position(|a| !a.iter().all(|x| x.is_finite())) {
        Some(m) => Err(Error::invalid("angles", format!("module {m}'s joint angles are not finite"))),
        None => Ok(()),
    }
}

/// Rotation by `angle` about coordinate axis `axis` (0: x, 1: y, 2: z).
fn axis_rotation(axis: usize, angle: f64) -> Matrix3<f64> {
    let (s, c) = angle.sin_cos();
    match axis {
        0 => Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c),
        1 => Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c),
        _ => Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0),
    }
}
