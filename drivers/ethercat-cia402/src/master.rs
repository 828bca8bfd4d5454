//! The EtherCAT master side, on [ethercrab](https://docs.rs/ethercrab): the bus brought
//! up from the drive file and the cyclic exchange.
//!
//! [`Bus::bring_up`] discovers the SubDevices (INIT → PRE-OP), checks that there is one
//! per `[[axis]]` and that each reports the identity the file expects (SII and object
//! 0x1018) before anything else is written, configures each drive over CoE SDO
//! ([`crate::pdo::configuration_plan`]: modes of operation 0x6060, max torque 0x6072,
//! RxPDO 0x1600 / TxPDO 0x1A00 assigned through 0x1C12 / 0x1C13), checks its rated
//! torque 0x6076 against the file, arms its process data watchdog (ESC registers 0x0400
//! and 0x0420, ETG.1000.4 6.3), sets up distributed clocks SYNC0 at the bus cycle where
//! the SubDevices support it (ETG.1000.4 9), and goes SAFE-OP → OP.
//!
//! [`Bus::exchange`] is one logical read-write of the whole process image per cycle,
//! bounded by a deadline shorter than the cycle: a frame not back in time is a lost
//! cycle ([`LostCycles`]), a wrong working counter or a SubDevice out of OP is a
//! [`CycleError`]. It polls ethercrab's future on the calling thread with its own
//! waker, so it needs no executor and takes no lock of its own.

use std::future::Future;
use std::mem::ManuallyDrop;
use std::pin::pin;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll, Wake, Waker};
use std::thread::{self, Thread, ThreadId};
use std::time::{Duration, Instant};

use ethercrab::error::Error;
use ethercrab::subdevice_group::{DcConfiguration, HasDc, NoDc, Op, PreOp};
use ethercrab::{
    DcSync, DefaultLock, MainDevice, MainDeviceConfig, PduLoop, PduRx, PduStorage, PduTx,
    SubDeviceGroup, SubDeviceState, Timeouts,
};

use crate::drive_file::{AxisConfig, DriveFile};
use crate::pdo::{self, Inputs, Outputs, RX_BYTES, SdoValue, TX_BYTES};

/// Most SubDevices on one bus (ethercrab needs a power of two).
pub const MAX_SUBDEVICES: usize = 16;
/// Bytes of the whole process image: 16 × (8 + 14) rounded up.
pub const PDI_LEN: usize = 512;
const MAX_FRAMES: usize = 16;
const MAX_PDU_DATA: usize = PduStorage::element_size(1100);

type Group<S, DC = NoDc> = SubDeviceGroup<MAX_SUBDEVICES, PDI_LEN, DefaultLock, S, DC>;

/// The numeric codes of faults this driver detects itself, as reported in
/// `Fault::code`. They lie above 0xFFFF so they never collide with a drive's own error
/// code (0x603F, 16 bit).
pub mod codes {
    /// More than `max_lost_cycles` exchanges in a row did not come back in time.
    pub const BUS_LOST: u32 = 0x00EC_0001;
    /// The working counter of the cyclic exchange was not the expected one.
    pub const WORKING_COUNTER: u32 = 0x00EC_0002;
    /// The drive went between two CiA 402 states the standard does not connect.
    pub const ILLEGAL_TRANSITION: u32 = 0x00EC_0003;
    /// The statusword (0x6041) matches no CiA 402 state.
    pub const UNDEFINED_STATUSWORD: u32 = 0x00EC_0004;
    /// A drive did not reach the commanded state in time.
    pub const STATE_TIMEOUT: u32 = 0x00EC_0005;
    /// Another ethercrab error in the cyclic exchange (frame, PDU, internal).
    pub const BUS_ERROR: u32 = 0x00EC_0006;
    /// The bus could not be brought up (discovery, SDO, state change).
    pub const BRING_UP: u32 = 0x00EC_0007;
    /// A SubDevice reports another vendor id or product code than the drive file.
    pub const WRONG_IDENTITY: u32 = 0x00EC_0008;
    /// The drive's rated torque 0x6076 differs from the drive file.
    pub const RATED_TORQUE: u32 = 0x00EC_0009;
    /// The bus has another number of SubDevices than the drive file has axes.
    pub const AXIS_COUNT: u32 = 0x00EC_000A;
    /// A SubDevice left OP: the low 16 bits are its AL status code (0x0134,
    /// ETG.1000.6 table 11).
    pub const LEFT_OP: u32 = 0x00ED_0000;

    /// The code of a SubDevice that left OP with AL status code `al_status_code`.
    pub const fn left_op(al_status_code: u16) -> u32 {
        LEFT_OP | al_status_code as u32
    }
}

/// Why the bus could not be brought up; the text names the axis and the values.
#[derive(Debug, thiserror::Error)]
pub enum BringUpError {
    /// The PDU storage was split already.
    #[error("the EtherCAT frame storage could not be set up")]
    Storage,
    /// The raw socket could not be opened.
    #[error(
        "cannot open a raw socket on `{interface}`: {source} (needs CAP_NET_RAW and the interface up)"
    )]
    Socket {
        /// The interface.
        interface: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// Discovery failed (no SubDevice answered, or an ethercrab error).
    #[error("discovery on the EtherCAT bus failed: {0}")]
    Discovery(Error),
    /// Another number of SubDevices than axes.
    #[error("the bus has {found} SubDevices, the drive file {expected} axes")]
    AxisCount {
        /// SubDevices found.
        found: usize,
        /// Axes in the drive file.
        expected: usize,
    },
    /// A SubDevice reports another identity than its axis in the drive file.
    #[error(
        "axis {axis} (joint {joint}): the drive at bus position {axis} is vendor {found_vendor:#010x} product {found_product:#010x} ({source_}), the drive file expects vendor {expected_vendor:#010x} product {expected_product:#010x}"
    )]
    WrongIdentity {
        /// Axis index (0-based, file order = bus order).
        axis: usize,
        /// Its joint.
        joint: String,
        /// Where the identity was read (`SII` or `0x1018`).
        source_: &'static str,
        /// Vendor id found.
        found_vendor: u32,
        /// Product code found.
        found_product: u32,
        /// Vendor id expected.
        expected_vendor: u32,
        /// Product code expected.
        expected_product: u32,
    },
    /// The rated torque 0x6076 differs from the drive file.
    #[error(
        "axis {axis} (joint {joint}): rated torque 0x6076 is {found_mnm} mN·m, the drive file says {expected_nm} N·m"
    )]
    RatedTorque {
        /// Axis index.
        axis: usize,
        /// Its joint.
        joint: String,
        /// 0x6076 as read (mN·m).
        found_mnm: u32,
        /// `rated_torque_nm` from the file.
        expected_nm: f64,
    },
    /// An SDO or register access during configuration failed.
    #[error("axis {axis} (joint {joint}): {what} ({object}): {source}")]
    Configure {
        /// Axis index.
        axis: usize,
        /// Its joint.
        joint: String,
        /// What was being set.
        what: &'static str,
        /// The object or register, e.g. `0x6060:00`.
        object: String,
        /// ethercrab's error (an SDO abort carries its code).
        source: Error,
    },
    /// The process image of an axis is not the mapped one.
    #[error(
        "axis {axis} (joint {joint}): process image is {inputs} input and {outputs} output bytes, the mapping gives {TX_BYTES} and {RX_BYTES}"
    )]
    Image {
        /// Axis index.
        axis: usize,
        /// Its joint.
        joint: String,
        /// Input bytes found.
        inputs: usize,
        /// Output bytes found.
        outputs: usize,
    },
    /// A drive watchdog that does not fit the ESC register.
    #[error(
        "axis {axis} (joint {joint}): drive_watchdog_ms {ms} does not fit the ESC watchdog (max 6553 ms)"
    )]
    Watchdog {
        /// Axis index.
        axis: usize,
        /// Its joint.
        joint: String,
        /// The value.
        ms: u32,
    },
    /// A state change of the group failed.
    #[error("bus to {state} failed: {source}")]
    State {
        /// The state asked for.
        state: &'static str,
        /// ethercrab's error.
        source: Error,
    },
}

impl BringUpError {
    /// The axis this error is about, if one.
    pub fn axis(&self) -> Option<usize> {
        match self {
            BringUpError::WrongIdentity { axis, .. }
            | BringUpError::RatedTorque { axis, .. }
            | BringUpError::Configure { axis, .. }
            | BringUpError::Image { axis, .. }
            | BringUpError::Watchdog { axis, .. } => Some(*axis),
            _ => None,
        }
    }

    /// The fault code for it ([`codes`]).
    pub fn code(&self) -> u32 {
        match self {
            BringUpError::WrongIdentity { .. } => codes::WRONG_IDENTITY,
            BringUpError::RatedTorque { .. } => codes::RATED_TORQUE,
            BringUpError::AxisCount { .. } => codes::AXIS_COUNT,
            _ => codes::BRING_UP,
        }
    }
}

/// What went wrong in one cyclic exchange.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CycleError {
    /// The frame did not come back before the deadline (a lost cycle).
    Lost,
    /// The SubDevice at `position` is not in OP; its AL status code (0 if it could not
    /// be read).
    LeftOp {
        /// Bus position (= axis index).
        position: usize,
        /// AL status code, register 0x0134.
        al_status_code: u16,
    },
    /// The working counter differs from the expected one.
    WorkingCounter {
        /// Received.
        got: u16,
        /// Expected.
        expected: u16,
    },
    /// Another ethercrab error.
    Bus,
}

/// Counts lost cycles in a row: up to `max` are ridden out, one more is a fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LostCycles {
    in_row: u32,
    max: u32,
    total: u64,
}

impl LostCycles {
    /// A counter that tolerates `max` lost cycles in a row (`max_lost_cycles`).
    pub const fn new(max: u32) -> LostCycles {
        LostCycles {
            in_row: 0,
            max,
            total: 0,
        }
    }

    /// A cycle came back: the run ends.
    pub fn ok(&mut self) {
        self.in_row = 0;
    }

    /// A cycle was lost; true if that makes more than `max` in a row (the bus is lost).
    pub fn lost(&mut self) -> bool {
        self.in_row = self.in_row.saturating_add(1);
        self.total += 1;
        self.in_row > self.max
    }

    /// Lost cycles in the current run.
    pub const fn in_row(&self) -> u32 {
        self.in_row
    }

    /// Lost cycles since start.
    pub const fn total(&self) -> u64 {
        self.total
    }
}

/// How long the AL status read after a SubDevice left OP may take at least (it names
/// the reason in the fault's code); well below the pipeline's default `stale_ms`.
pub const AL_STATUS_TIMEOUT: Duration = Duration::from_millis(20);

/// The ethercrab timeouts used for bring-up (the cyclic exchange has its own deadline):
/// a frame or an EEPROM access may take 100 ms, so that a scheduling hiccup of the
/// host does not fail a bring-up.
pub fn timeouts() -> Timeouts {
    Timeouts {
        state_transition: Duration::from_secs(5),
        pdu: Duration::from_millis(100),
        eeprom: Duration::from_millis(100),
        ..Timeouts::default()
    }
}

/// The ethercrab MainDevice configuration: a short static DC drift compensation.
pub fn maindevice_config() -> MainDeviceConfig {
    MainDeviceConfig {
        dc_static_sync_iterations: 1000,
        ..MainDeviceConfig::default()
    }
}

/// A PDU loop's three handles: the transport's halves and the MainDevice's.
pub type PduHalves = (PduTx<'static>, PduRx<'static>, PduLoop<'static>);

/// PDU loops not in use, each on a storage that lives for the rest of the process.
static IDLE_PDU_LOOPS: Mutex<Vec<PduHalves>> = Mutex::new(Vec::new());
/// Storages made so far in this process.
static PDU_STORAGES: AtomicUsize = AtomicUsize::new(0);

/// A PDU loop for a bring-up: an idle one if there is one, else one on a new storage.
///
/// ethercrab's MainDevice needs its storage for `'static` and splits a storage only
/// once, so a storage is never freed; instead a [`Transport`] hands its loop back when
/// it is dropped (the MainDevice released with `release_all`, the halves back from the
/// link's thread and reset) and the next bring-up takes it again. A process thus makes
/// as many storages as it ever has transports at once — one in the driver, whatever
/// the number of resets — instead of one per bring-up.
pub fn pdu_loop() -> Result<PduHalves, BringUpError> {
    if let Some(idle) = IDLE_PDU_LOOPS.lock().ok().and_then(|mut v| v.pop()) {
        return Ok(idle);
    }
    let storage: &'static PduStorage<MAX_FRAMES, MAX_PDU_DATA> =
        Box::leak(Box::new(PduStorage::new()));
    PDU_STORAGES.fetch_add(1, Ordering::Relaxed);
    storage.try_split().map_err(|()| BringUpError::Storage)
}

/// How many PDU storages this process has made ([`pdu_loop`]).
pub fn pdu_storages() -> usize {
    PDU_STORAGES.load(Ordering::Relaxed)
}

/// What carries a MainDevice's frames (a socket thread, an in-process link). Stopped
/// when its [`Transport`] is dropped, it gives back the halves it was given (None if it
/// cannot: their storage is then not reused). A closure does, so a link from another
/// crate is passed as `move || link.stop()`.
pub trait Link: Send {
    /// Stops carrying frames and returns the PDU loop halves.
    fn stop(self: Box<Self>) -> Option<(PduTx<'static>, PduRx<'static>)>;
}

impl<F> Link for F
where
    F: FnOnce() -> Option<(PduTx<'static>, PduRx<'static>)> + Send,
{
    fn stop(self: Box<Self>) -> Option<(PduTx<'static>, PduRx<'static>)> {
        (*self)()
    }
}

/// A MainDevice and whatever keeps its frames moving (a socket thread, an in-process
/// link), owned together. Dropping it stops the link and gives the PDU loop back for
/// the next bring-up ([`pdu_loop`]).
pub struct Transport {
    /// Taken out only in `drop`.
    maindevice: ManuallyDrop<MainDevice<'static>>,
    link: Option<Box<dyn Link>>,
    frame_guard: Option<Arc<FrameGuard>>,
}

impl Drop for Transport {
    fn drop(&mut self) {
        // SAFETY: taken once, here, and not used after.
        let md = unsafe { ManuallyDrop::take(&mut self.maindevice) };
        // SAFETY: a group configured on this MainDevice is never used with another: a
        // `Bus` owns its group beside this transport and both go together. Frames still
        // in flight are dropped: `release_all` resets every frame and makes the link's
        // thread stop (and ignore what it receives meanwhile).
        let pdu_loop = unsafe { md.release_all() };
        let Some((tx, rx)) = self.link.take().and_then(|l| l.stop()) else {
            return;
        };
        if let Ok(mut idle) = IDLE_PDU_LOOPS.lock() {
            idle.push((tx.release(), rx.release(), pdu_loop));
        }
    }
}

/// Mutual exclusion between a transport handing a frame to ethercrab's PDU loop (claim
/// and send, or receive) and the master giving up on that frame at its deadline.
/// ethercrab marks a frame sent (or received) without checking that the waiting future
/// still exists; a future dropped in between leaks the frame slot for good. The
/// transport holds the guard around each hand-over (a copy of the frame and a state
/// change, no syscall), the master around the drop only, so it is contended only at a
/// missed deadline, and then briefly.
#[derive(Debug, Default)]
pub struct FrameGuard(std::sync::atomic::AtomicBool);

impl FrameGuard {
    /// Runs `f` holding the guard. While the other side holds it: spins a little, then
    /// sleeps in 20 µs steps — the holder may be preempted, and a yield from a
    /// SCHED_FIFO cycle thread would never let a normal-priority holder run.
    pub fn hold<T>(&self, f: impl FnOnce() -> T) -> T {
        use std::sync::atomic::Ordering;
        let mut spins = 0u32;
        while self
            .0
            .compare_exchange_weak(false, true, Ordering::Acquire, Ordering::Relaxed)
            .is_err()
        {
            spins += 1;
            if spins < 64 {
                std::hint::spin_loop();
            } else {
                thread::sleep(Duration::from_micros(20));
            }
        }
        let r = f();
        self.0.store(false, Ordering::Release);
        r
    }
}

impl Transport {
    /// A MainDevice on `pdu_loop` whose frames `link` carries (stopped with it).
    pub fn new(pdu_loop: PduLoop<'static>, link: impl Link + 'static) -> Transport {
        Transport {
            maindevice: ManuallyDrop::new(MainDevice::new(
                pdu_loop,
                timeouts(),
                maindevice_config(),
            )),
            link: Some(Box::new(link)),
            frame_guard: None,
        }
    }

    /// The same, with the transport holding `guard` around every frame hand-over.
    pub fn with_frame_guard(
        pdu_loop: PduLoop<'static>,
        link: impl Link + 'static,
        guard: Arc<FrameGuard>,
    ) -> Transport {
        let mut t = Transport::new(pdu_loop, link);
        t.frame_guard = Some(guard);
        t
    }

    /// A MainDevice on a raw socket (AF_PACKET) on `interface`, its frames carried by
    /// [`crate::raw_socket::RawSocketLink`] (a late frame is dropped, not fatal) on a
    /// thread with the real-time settings `rt`.
    pub fn raw_socket(
        interface: &str,
        rt: Option<crate::raw_socket::TransportRt>,
    ) -> Result<Transport, BringUpError> {
        let (tx, rx, pdu_loop) = pdu_loop()?;
        let guard = Arc::new(FrameGuard::default());
        let link =
            crate::raw_socket::RawSocketLink::spawn(interface, tx, rx, Arc::clone(&guard), rt)
                .map_err(|source| BringUpError::Socket {
                    interface: interface.to_string(),
                    source,
                })?;
        Ok(Transport::with_frame_guard(pdu_loop, link, guard))
    }
}

/// Wakes the thread polling an exchange.
struct ThreadWaker(Thread);

impl Wake for ThreadWaker {
    fn wake(self: Arc<Self>) {
        self.0.unpark();
    }
    fn wake_by_ref(self: &Arc<Self>) {
        self.0.unpark();
    }
}

/// Polls `fut` on this thread until it completes or `deadline` passes (`None`; the
/// future is dropped, which releases its frame, under `guard` if the transport has one).
fn poll_until<F: Future>(
    fut: F,
    deadline: Instant,
    waker: &Waker,
    guard: Option<&FrameGuard>,
) -> Option<F::Output> {
    // On the stack, dropped in place (`set(None)`) when the deadline passes.
    let mut fut = pin!(Some(fut));
    let mut cx = Context::from_waker(waker);
    loop {
        if let Some(f) = fut.as_mut().as_pin_mut()
            && let Poll::Ready(v) = f.poll(&mut cx)
        {
            return Some(v);
        }
        let now = Instant::now();
        if now >= deadline {
            match guard {
                Some(g) => g.hold(|| fut.set(None)),
                None => fut.set(None),
            }
            return None;
        }
        thread::park_timeout(deadline - now);
    }
}

enum OpGroup {
    Free(Group<Op>),
    Dc(Group<Op, HasDc>),
}

/// A summary of one exchange's response.
struct Response {
    wkc: u16,
    not_op: Option<usize>,
}

fn summarize<E>(r: &ethercrab::subdevice_group::TxRxResponse<MAX_SUBDEVICES, E>) -> Response {
    Response {
        wkc: r.working_counter,
        not_op: r
            .subdevice_states
            .iter()
            .position(|s| *s != SubDeviceState::Op),
    }
}

/// The bus in OP: the group, its process image and the cyclic exchange.
pub struct Bus {
    transport: Transport,
    group: Option<OpGroup>,
    axes: usize,
    expected_wkc: u16,
    exchange_timeout: Duration,
    waker: Option<(ThreadId, Waker)>,
    dc: bool,
}

fn configure_err(
    axis: usize,
    cfg: &AxisConfig,
    what: &'static str,
    object: String,
) -> impl FnOnce(Error) -> BringUpError {
    let joint = cfg.joint.clone();
    move |source| BringUpError::Configure {
        axis,
        joint,
        what,
        object,
        source,
    }
}

impl Bus {
    /// Brings the bus described by `file` up to OP over `transport` (see the module
    /// documentation). Nothing is written to a drive before every identity is checked.
    /// `exchange_timeout` bounds each cyclic exchange; it should be shorter than the
    /// cycle.
    pub fn bring_up(
        transport: Transport,
        file: &DriveFile,
        exchange_timeout: Duration,
    ) -> Result<Bus, BringUpError> {
        let period = Duration::from_micros(u64::from(file.bus.cycle_us));
        let md = &transport.maindevice;
        let (group, dc) = async_io::block_on(async {
            let mut group: Group<PreOp> = md
                .init_single_group::<MAX_SUBDEVICES, PDI_LEN>(ethercrab::std::ethercat_now)
                .await
                .map_err(BringUpError::Discovery)?;
            if group.len() != file.axes.len() {
                return Err(BringUpError::AxisCount {
                    found: group.len(),
                    expected: file.axes.len(),
                });
            }
            // Identities first (SII, read at discovery), before any write.
            for (i, (sd, cfg)) in group.iter(md).zip(&file.axes).enumerate() {
                let id = sd.identity();
                check_identity(i, cfg, "SII", id.vendor_id, id.product_id)?;
            }
            // Then 0x1018 over CoE, still before anything is written.
            for (i, (sd, cfg)) in group.iter(md).zip(&file.axes).enumerate() {
                let vendor = sd.sdo_read::<u32>(0x1018, 1).await.map_err(configure_err(
                    i,
                    cfg,
                    "identity",
                    "0x1018:01".into(),
                ))?;
                let product = sd.sdo_read::<u32>(0x1018, 2).await.map_err(configure_err(
                    i,
                    cfg,
                    "identity",
                    "0x1018:02".into(),
                ))?;
                check_identity(i, cfg, "0x1018", vendor, product)?;
            }
            let mut any_dc = false;
            for (i, (mut sd, cfg)) in group.iter_mut(md).zip(&file.axes).enumerate() {
                let rated = sd.sdo_read::<u32>(0x6076, 0).await.map_err(configure_err(
                    i,
                    cfg,
                    "rated torque",
                    "0x6076:00".into(),
                ))?;
                if !rated_torque_matches(rated, cfg.rated_torque_nm) {
                    return Err(BringUpError::RatedTorque {
                        axis: i,
                        joint: cfg.joint.clone(),
                        found_mnm: rated,
                        expected_nm: cfg.rated_torque_nm,
                    });
                }
                for step in pdo::configuration_plan(cfg) {
                    let object = format!("{:#06x}:{:02x}", step.index, step.sub);
                    let r = match step.value {
                        SdoValue::U8(v) => sd.sdo_write(step.index, step.sub, v).await,
                        SdoValue::I8(v) => sd.sdo_write(step.index, step.sub, v).await,
                        SdoValue::U16(v) => sd.sdo_write(step.index, step.sub, v).await,
                        SdoValue::U32(v) => sd.sdo_write(step.index, step.sub, v).await,
                    };
                    r.map_err(configure_err(i, cfg, step.what, object))?;
                }
                let Some(wd) = pdo::sm_watchdog_time(cfg.drive_watchdog_ms) else {
                    return Err(BringUpError::Watchdog {
                        axis: i,
                        joint: cfg.joint.clone(),
                        ms: cfg.drive_watchdog_ms,
                    });
                };
                sd.register_write(0x0400u16, pdo::WATCHDOG_DIVIDER)
                    .await
                    .map_err(configure_err(
                        i,
                        cfg,
                        "watchdog divider",
                        "ESC 0x0400".into(),
                    ))?;
                sd.register_write(0x0420u16, wd)
                    .await
                    .map_err(configure_err(
                        i,
                        cfg,
                        "process data watchdog",
                        "ESC 0x0420".into(),
                    ))?;
                if sd.dc_support().any() {
                    sd.set_dc_sync(DcSync::Sync0);
                    any_dc = true;
                }
            }
            let state = |state: &'static str| move |source| BringUpError::State { state, source };
            let group = group
                .into_pre_op_pdi(md)
                .await
                .map_err(state("PRE-OP with process data"))?;
            if any_dc {
                let group = group
                    .configure_dc_sync(
                        md,
                        DcConfiguration {
                            start_delay: Duration::from_millis(100),
                            sync0_period: period,
                            sync0_shift: period / 2,
                        },
                    )
                    .await
                    .map_err(state("distributed clocks"))?;
                let group = group.into_safe_op(md).await.map_err(state("SAFE-OP"))?;
                let group = group.request_into_op(md).await.map_err(state("OP"))?;
                // With SYNC0 running, the SubDevices reach OP only while process data
                // flows: cycle until they are all there.
                let start = Instant::now();
                loop {
                    let r = group.tx_rx_dc(md).await.map_err(state("OP"))?;
                    if r.all_op() {
                        break;
                    }
                    if start.elapsed() > timeouts().state_transition {
                        return Err(BringUpError::State {
                            state: "OP",
                            source: Error::Timeout(ethercrab::error::TimeoutError::StateTransition),
                        });
                    }
                    async_io::Timer::after(period).await;
                }
                Ok((OpGroup::Dc(group), true))
            } else {
                let group = group.into_safe_op(md).await.map_err(state("SAFE-OP"))?;
                let group = group.into_op(md).await.map_err(state("OP"))?;
                Ok((OpGroup::Free(group), false))
            }
        })?;
        let mut images = Vec::with_capacity(file.axes.len());
        for (i, cfg) in file.axes.iter().enumerate() {
            let (inputs, outputs) =
                image_sizes(&group, md, i).map_err(|source| BringUpError::State {
                    state: "OP",
                    source,
                })?;
            if inputs != TX_BYTES || outputs != RX_BYTES {
                return Err(BringUpError::Image {
                    axis: i,
                    joint: cfg.joint.clone(),
                    inputs,
                    outputs,
                });
            }
            images.push((inputs, outputs));
        }
        Ok(Bus {
            axes: file.axes.len(),
            expected_wkc: pdo::expected_working_counter(images),
            transport,
            group: Some(group),
            exchange_timeout,
            waker: None,
            dc,
        })
    }

    /// Number of axes (SubDevices) on the bus.
    pub fn axes(&self) -> usize {
        self.axes
    }

    /// Whether the SubDevices run on distributed clocks (SYNC0 at the cycle).
    pub fn distributed_clocks(&self) -> bool {
        self.dc
    }

    /// The working counter a full exchange returns.
    pub fn expected_working_counter(&self) -> u16 {
        self.expected_wkc
    }

    fn waker(&mut self) -> Waker {
        let me = thread::current();
        match &self.waker {
            Some((id, w)) if *id == me.id() => w.clone(),
            _ => {
                let w = Waker::from(Arc::new(ThreadWaker(me.clone())));
                self.waker = Some((me.id(), w.clone()));
                w
            }
        }
    }

    /// One cyclic exchange: sends the outputs, receives the inputs, checks that every
    /// SubDevice is in OP and the working counter. Returns within the exchange timeout
    /// (plus one AL status read when a SubDevice left OP).
    pub fn exchange(&mut self) -> Result<(), CycleError> {
        let waker = self.waker();
        let deadline = Instant::now() + self.exchange_timeout;
        let md = &self.transport.maindevice;
        let guard = self.transport.frame_guard.as_deref();
        let resp = match &self.group {
            Some(OpGroup::Free(g)) => {
                poll_until(g.tx_rx(md), deadline, &waker, guard).map(|r| r.map(|r| summarize(&r)))
            }
            Some(OpGroup::Dc(g)) => poll_until(g.tx_rx_dc(md), deadline, &waker, guard)
                .map(|r| r.map(|r| summarize(&r))),
            None => return Err(CycleError::Bus),
        };
        let resp = match resp {
            None | Some(Err(Error::Timeout(_))) => return Err(CycleError::Lost),
            Some(Err(_)) => return Err(CycleError::Bus),
            Some(Ok(r)) => r,
        };
        if let Some(position) = resp.not_op {
            // The cycle fails anyway: the AL status code that says why is worth waiting
            // a little longer than an exchange for (on a loaded host a read bounded by
            // the exchange timeout lost it, and the fault said code 0).
            let deadline = Instant::now() + self.exchange_timeout.max(AL_STATUS_TIMEOUT);
            return Err(CycleError::LeftOp {
                position,
                al_status_code: self.al_status_code(position, deadline, &waker),
            });
        }
        if resp.wkc != self.expected_wkc {
            return Err(CycleError::WorkingCounter {
                got: resp.wkc,
                expected: self.expected_wkc,
            });
        }
        Ok(())
    }

    fn al_status_code(&self, position: usize, deadline: Instant, waker: &Waker) -> u16 {
        let md = &self.transport.maindevice;
        let guard = self.transport.frame_guard.as_deref();
        let status = match &self.group {
            Some(OpGroup::Free(g)) => g.subdevice(md, position).ok().and_then(|sd| {
                poll_until(async move { sd.status().await }, deadline, waker, guard)
            }),
            Some(OpGroup::Dc(g)) => g.subdevice(md, position).ok().and_then(|sd| {
                poll_until(async move { sd.status().await }, deadline, waker, guard)
            }),
            None => None,
        };
        match status {
            Some(Ok((_, code))) | Some(Err(Error::SubDevice(code))) => u16::from(code),
            _ => 0,
        }
    }

    /// The inputs of axis `i` from the last exchange.
    pub fn inputs(&self, i: usize) -> Option<Inputs> {
        let md = &self.transport.maindevice;
        match &self.group {
            Some(OpGroup::Free(g)) => Inputs::decode(g.subdevice(md, i).ok()?.io_raw().inputs()),
            Some(OpGroup::Dc(g)) => Inputs::decode(g.subdevice(md, i).ok()?.io_raw().inputs()),
            None => None,
        }
    }

    /// Sets the outputs of axis `i` for the next exchange; false if there is no such
    /// axis.
    pub fn set_outputs(&self, i: usize, outputs: &Outputs) -> bool {
        let md = &self.transport.maindevice;
        match &self.group {
            Some(OpGroup::Free(g)) => g
                .subdevice(md, i)
                .is_ok_and(|sd| outputs.encode(sd.io_raw_mut().outputs())),
            Some(OpGroup::Dc(g)) => g
                .subdevice(md, i)
                .is_ok_and(|sd| outputs.encode(sd.io_raw_mut().outputs())),
            None => false,
        }
    }

    /// Takes the bus down to SAFE-OP, then PRE-OP and INIT (outputs stop acting at
    /// SAFE-OP). Errors are ignored: this is the last thing done.
    pub fn shut_down(&mut self) {
        let md = &self.transport.maindevice;
        let Some(group) = self.group.take() else {
            return;
        };
        async_io::block_on(async {
            match group {
                OpGroup::Free(g) => {
                    if let Ok(g) = g.into_safe_op(md).await
                        && let Ok(g) = g.into_pre_op(md).await
                    {
                        let _ = g.into_init(md).await;
                    }
                }
                OpGroup::Dc(g) => {
                    if let Ok(g) = g.into_safe_op(md).await
                        && let Ok(g) = g.into_pre_op(md).await
                    {
                        let _ = g.into_init(md).await;
                    }
                }
            }
        });
    }
}

fn image_sizes(
    group: &OpGroup,
    md: &MainDevice<'static>,
    i: usize,
) -> Result<(usize, usize), Error> {
    Ok(match group {
        OpGroup::Free(g) => {
            let sd = g.subdevice(md, i)?;
            let io = sd.io_raw();
            (io.inputs().len(), io.outputs().len())
        }
        OpGroup::Dc(g) => {
            let sd = g.subdevice(md, i)?;
            let io = sd.io_raw();
            (io.inputs().len(), io.outputs().len())
        }
    })
}

fn check_identity(
    axis: usize,
    cfg: &AxisConfig,
    source_: &'static str,
    vendor: u32,
    product: u32,
) -> Result<(), BringUpError> {
    if vendor == cfg.vendor_id && product == cfg.product_code {
        return Ok(());
    }
    Err(BringUpError::WrongIdentity {
        axis,
        joint: cfg.joint.clone(),
        source_,
        found_vendor: vendor,
        found_product: product,
        expected_vendor: cfg.vendor_id,
        expected_product: cfg.product_code,
    })
}

/// Whether a rated torque 0x6076 read from the drive (mN·m, CiA 402 6.8.1) matches the
/// drive file's `rated_torque_nm`: within 1 mN·m or 0.1 %, whichever is larger.
pub fn rated_torque_matches(found_mnm: u32, expected_nm: f64) -> bool {
    let expected_mnm = expected_nm * 1000.0;
    let tol = (expected_mnm.abs() * 1e-3).max(1.0);
    (f64::from(found_mnm) - expected_mnm).abs() <= tol
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lost_cycles_are_ridden_out_up_to_the_limit() {
        let mut l = LostCycles::new(3);
        assert!(!l.lost());
        assert!(!l.lost());
        assert!(!l.lost());
        l.ok();
        assert_eq!(l.in_row(), 0);
        for _ in 0..3 {
            assert!(!l.lost());
        }
        assert!(l.lost(), "the fourth in a row is one too many");
        assert_eq!(l.total(), 7);
        let mut none = LostCycles::new(0);
        assert!(none.lost(), "max 0: the first loss is a fault");
    }

    #[test]
    fn an_exchange_is_bounded_by_its_deadline_and_dropped_under_the_guard() {
        let waker = Waker::from(Arc::new(ThreadWaker(thread::current())));
        let guard = FrameGuard::default();
        let t0 = Instant::now();
        let r = poll_until(
            std::future::pending::<()>(),
            t0 + Duration::from_millis(5),
            &waker,
            Some(&guard),
        );
        assert_eq!(r, None);
        let dt = t0.elapsed();
        assert!(dt >= Duration::from_millis(5), "{dt:?}");
        assert_eq!(
            poll_until(async { 7 }, Instant::now(), &waker, None),
            Some(7)
        );
        // The guard is free again and excludes the other side while held.
        let held = guard.hold(|| guard.0.load(std::sync::atomic::Ordering::Relaxed));
        assert!(held);
        assert!(!guard.0.load(std::sync::atomic::Ordering::Relaxed));
    }

    #[test]
    fn rated_torque_tolerance() {
        assert!(rated_torque_matches(1270, 1.27));
        assert!(rated_torque_matches(1271, 1.27));
        assert!(!rated_torque_matches(1273, 1.27));
        assert!(rated_torque_matches(640, 0.64));
        assert!(!rated_torque_matches(1270, 0.64));
    }

    #[test]
    fn codes_keep_clear_of_drive_error_codes() {
        assert_eq!(codes::left_op(0x001B), 0x00ED_001B);
        for c in [
            codes::BUS_LOST,
            codes::WORKING_COUNTER,
            codes::ILLEGAL_TRANSITION,
            codes::UNDEFINED_STATUSWORD,
            codes::STATE_TIMEOUT,
            codes::BUS_ERROR,
            codes::BRING_UP,
            codes::WRONG_IDENTITY,
            codes::RATED_TORQUE,
            codes::AXIS_COUNT,
        ] {
            assert!(c > 0xFFFF);
        }
    }
}
