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

use crate::dc::{
    self, PhaseLock, PhaseStats, SM_INPUT_PARAMETER, SM_OUTPUT_PARAMETER, sub, sync_mode,
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
    /// A drive cannot run synchronised to DC SYNC0 at the bus cycle (0x1C32:04/05).
    pub const DC_CONFIG: u32 = 0x00EC_000B;
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
    /// A drive with distributed clocks that offers no DC SYNC0 sync mode (0x1C32:04).
    #[error(
        "axis {axis} (joint {joint}, bus position {axis}, vendor {vendor:#010x} product {product:#010x}): the drive offers no DC SYNC0 synchronisation (0x1C32:04 sync modes supported = {supported:#06x})"
    )]
    DcUnsupported {
        /// Axis index (= bus position).
        axis: usize,
        /// Its joint.
        joint: String,
        /// Vendor id.
        vendor: u32,
        /// Product code.
        product: u32,
        /// 0x1C32:04 as read.
        supported: u16,
    },
    /// The bus cycle is shorter than a drive's minimum cycle time (0x1C32:05).
    #[error(
        "axis {axis} (joint {joint}, bus position {axis}, vendor {vendor:#010x} product {product:#010x}): bus.cycle_us {cycle_us} µs is below the drive's minimum cycle time 0x1C32:05 = {min_ns} ns"
    )]
    CycleTooShort {
        /// Axis index (= bus position).
        axis: usize,
        /// Its joint.
        joint: String,
        /// Vendor id.
        vendor: u32,
        /// Product code.
        product: u32,
        /// The bus cycle (µs).
        cycle_us: u32,
        /// 0x1C32:05 as read (ns).
        min_ns: u32,
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
            | BringUpError::DcUnsupported { axis, .. }
            | BringUpError::CycleTooShort { axis, .. }
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
            BringUpError::DcUnsupported { .. } | BringUpError::CycleTooShort { .. } => {
                codes::DC_CONFIG
            }
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
    /// DC system time of the reference clock as the frame passed it.
    dc_ns: Option<u64>,
}

fn summarize<E>(r: &ethercrab::subdevice_group::TxRxResponse<MAX_SUBDEVICES, E>) -> Response {
    Response {
        wkc: r.working_counter,
        not_op: r
            .subdevice_states
            .iter()
            .position(|s| *s != SubDeviceState::Op),
        dc_ns: None,
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
    /// With DC: the phase of the exchange against SYNC0, the bus position of the
    /// reference clock (the first SubDevice with DC, as ethercrab picks it)
    /// and the system time offset (0x0920) last written to it.
    phase: Option<(PhaseLock, usize, u64)>,
}

/// Options of [`Bus::bring_up_with`].
#[derive(Debug, Clone, Copy)]
pub struct BringUpOptions {
    /// Bounds each cyclic exchange; shorter than the cycle.
    pub exchange_timeout: Duration,
    /// With DC: how long after the frame reaches the drives their SYNC0 should come
    /// (the outputs' margin), see [`PhaseLock`]. `None`: the exchange timeout, at most
    /// half the cycle, so that an exchange back in time also reached the drives before
    /// SYNC0.
    pub sync0_margin: Option<Duration>,
}

/// 0x1C32:0B and 0x1C32:20 of one drive, read back over SDO.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SyncCounters {
    /// SM-event missed counter.
    pub sm_event_missed: u16,
    /// Sync error.
    pub sync_error: bool,
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
        Bus::bring_up_with(
            transport,
            file,
            BringUpOptions {
                exchange_timeout,
                sync0_margin: None,
            },
        )
    }

    /// [`Bus::bring_up`] with all its options.
    pub fn bring_up_with(
        transport: Transport,
        file: &DriveFile,
        options: BringUpOptions,
    ) -> Result<Bus, BringUpError> {
        let exchange_timeout = options.exchange_timeout;
        let period = Duration::from_micros(u64::from(file.bus.cycle_us));
        let period_ns = period.as_nanos() as u64;
        let margin_ns = options
            .sync0_margin
            .unwrap_or(exchange_timeout.min(period / 2))
            .as_nanos()
            .min(u128::from(period_ns)) as u64;
        let mut phase = PhaseLock::new(period_ns, 0, margin_ns);
        let mut dc_reference = None;
        let md = &transport.maindevice;
        let (group, reference_offset) = async_io::block_on(async {
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
                    configure_sync_parameters(&sd, i, cfg, period_ns).await?;
                    sd.set_dc_sync(DcSync::Sync0);
                    dc_reference.get_or_insert(i);
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
                            // Only enters ethercrab's `next_cycle_wait`, which the
                            // driver does not use: the exchange is the pipeline's, and
                            // the SYNC0 grid is moved onto it (`PhaseLock`).
                            sync0_shift: Duration::ZERO,
                        },
                    )
                    .await
                    .map_err(state("distributed clocks"))?;
                // The first SYNC0 (system time, as ethercrab rounded it), read back from
                // the reference clock: bring-up ends once SYNC0 runs, so the drives
                // take outputs from the first cycle of the pipeline on.
                let sync0_start = match dc_reference {
                    Some(r) => group
                        .subdevice(md, r)
                        .map_err(state("distributed clocks"))?
                        .register_read::<u64>(0x0990u16)
                        .await
                        .map_err(state("distributed clocks"))?,
                    None => 0,
                };
                let group = group.into_safe_op(md).await.map_err(state("SAFE-OP"))?;
                let group = group.request_into_op(md).await.map_err(state("OP"))?;
                // With SYNC0 running, the SubDevices reach OP only while process data
                // flows: cycle until they are all there and SYNC0 has run two cycles.
                let start = Instant::now();
                loop {
                    let r = group.tx_rx_dc(md).await.map_err(state("OP"))?;
                    phase.on_exchange(r.extra.dc_system_time);
                    let sync0_runs =
                        r.extra.dc_system_time >= sync0_start.saturating_add(2 * period_ns);
                    if r.all_op() && sync0_runs {
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
                // The reference clock's system time offset, which the phase is kept
                // with (`Bus::keep_phase`).
                let offset = match dc_reference {
                    Some(r) => group
                        .subdevice(md, r)
                        .map_err(state("distributed clocks"))?
                        .register_read::<u64>(0x0920u16)
                        .await
                        .map_err(state("distributed clocks"))?,
                    None => 0,
                };
                Ok((OpGroup::Dc(group), Some(offset)))
            } else {
                let group = group.into_safe_op(md).await.map_err(state("SAFE-OP"))?;
                let group = group.into_op(md).await.map_err(state("OP"))?;
                Ok((OpGroup::Free(group), None))
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
        let dc = reference_offset.is_some();
        let phase = match (reference_offset, dc_reference) {
            (Some(offset), Some(r)) => {
                let st = phase.stats();
                tracing::info!(
                    "EtherCAT DC: SYNC0 every {} µs, sync mode DC SYNC0 (0x1C32:01 = 2) on every DC drive, reference clock at bus position {r}; SYNC0 is to fall {} µs after the frame reaches the drives and is moved onto the pipeline's exchanges in their first ~100 ms (the bring-up's own exchanges had a margin of {} µs)",
                    period_ns / 1000,
                    st.target_margin_ns / 1000,
                    st.last_margin_ns / 1000,
                );
                Some((PhaseLock::new(period_ns, 0, margin_ns), r, offset))
            }
            _ => None,
        };
        Ok(Bus {
            axes: file.axes.len(),
            expected_wkc: pdo::expected_working_counter(images),
            transport,
            group: Some(group),
            exchange_timeout,
            waker: None,
            dc,
            phase,
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
            Some(OpGroup::Dc(g)) => poll_until(g.tx_rx_dc(md), deadline, &waker, guard).map(|r| {
                r.map(|r| Response {
                    dc_ns: Some(r.extra.dc_system_time),
                    ..summarize(&r)
                })
            }),
            None => return Err(CycleError::Bus),
        };
        let resp = match resp {
            None | Some(Err(Error::Timeout(_))) => return Err(CycleError::Lost),
            Some(Err(_)) => return Err(CycleError::Bus),
            Some(Ok(r)) => r,
        };
        if let Some(dc_ns) = resp.dc_ns {
            self.keep_phase(dc_ns, deadline, &waker);
        }
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

    /// Measures the exchange whose frame passed the reference clock at `dc_ns` and, once
    /// per window, moves the SYNC0 grid onto the exchanges ([`PhaseLock`]): the shift is
    /// added to the reference clock's system time offset (FPWR 0x0920, ETG.1000.4 9.1),
    /// which steps its system time; the other clocks follow it through the FRMW of
    /// every exchange (their drift control, ETG.1000.4 9.2). The offset is the one read
    /// at bring-up plus every shift since, so the write does not depend on how long the
    /// frame takes (writing an absolute system time to 0x0910 instead would put the
    /// write frame's own latency, hundreds of µs on a loaded host, into the phase).
    /// Bounded by the exchange's deadline; a write that does not come back is taken as
    /// not applied (the next window measures what did happen and corrects it).
    fn keep_phase(&mut self, dc_ns: u64, deadline: Instant, waker: &Waker) {
        let Some((lock, reference, offset)) = self.phase.as_mut() else {
            return;
        };
        let acquisitions = lock.stats().acquisitions;
        let Some(shift) = lock.on_exchange(dc_ns) else {
            return;
        };
        let st = lock.stats();
        let reference = *reference;
        let value = offset.wrapping_add_signed(shift);
        let md = &self.transport.maindevice;
        let guard = self.transport.frame_guard.as_deref();
        let Some(OpGroup::Dc(g)) = &self.group else {
            return;
        };
        let Ok(sd) = g.subdevice(md, reference) else {
            return;
        };
        let written = poll_until(
            async move { sd.register_write(0x0920u16, value).await },
            deadline,
            waker,
            guard,
        );
        if let Some(Ok(_)) = written
            && let Some((_, _, offset)) = self.phase.as_mut()
        {
            *offset = value;
        }
        if st.acquisitions != acquisitions {
            // Rare (the first window, a restarted pipeline timer): not per cycle.
            tracing::info!(
                "EtherCAT DC: SYNC0 moved onto the exchanges: DC system time shifted by {} µs (median margin was {} µs, target {} µs)",
                shift as f64 / 1000.0,
                st.window_median_margin_ns / 1000,
                st.target_margin_ns / 1000
            );
        }
    }

    /// With DC: the phase of the exchanges against SYNC0 so far.
    pub fn phase(&self) -> Option<PhaseStats> {
        self.phase.as_ref().map(|(l, _, _)| l.stats())
    }

    /// With DC: 0x1C32:0B (SM-event missed) and 0x1C32:20 (sync error) of every axis,
    /// read over SDO (not cyclic: at shut-down or after a fault); `None` for an axis
    /// whose read failed (or a drive without them) and for every axis after it.
    pub fn sync_counters(&self) -> Vec<Option<SyncCounters>> {
        let md = &self.transport.maindevice;
        let Some(OpGroup::Dc(g)) = &self.group else {
            return Vec::new();
        };
        // A drive that does not answer ends the reads: the bus is likely gone, and each
        // read would wait out ethercrab's mailbox timeout.
        let mut answering = true;
        (0..self.axes)
            .map(|i| {
                if !answering {
                    return None;
                }
                let sd = g.subdevice(md, i).ok()?;
                let c = async_io::block_on(async {
                    let missed = sd
                        .sdo_read::<u16>(SM_OUTPUT_PARAMETER, sub::SM_EVENT_MISSED)
                        .await
                        .ok()?;
                    let error = sd
                        .sdo_read::<u8>(SM_OUTPUT_PARAMETER, sub::SYNC_ERROR)
                        .await
                        .ok()?;
                    Some(SyncCounters {
                        sm_event_missed: missed,
                        sync_error: error != 0,
                    })
                });
                answering = c.is_some();
                c
            })
            .collect()
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

/// PRE-OP, axis `i` with distributed clocks: reads 0x1C32:04 (sync modes supported)
/// and 0x1C32:05 (minimum cycle time), refuses a drive without DC SYNC0 or a bus cycle
/// below its minimum, then writes sync mode DC SYNC0 and the cycle time into 0x1C32
/// and 0x1C33 (ETG.1020 / ETG.6010). A drive without 0x1C32 is left as it is (SYNC0
/// still configured, as for drives whose sync mode follows the ESC's DC activation).
/// 0x1C33 writes a drive refuses are ignored: many derive 0x1C33:01 from 0x1C32:01.
async fn configure_sync_parameters<S: std::ops::Deref<Target = ethercrab::SubDevice>>(
    sd: &ethercrab::SubDeviceRef<'_, S>,
    axis: usize,
    cfg: &AxisConfig,
    period_ns: u64,
) -> Result<(), BringUpError> {
    use ethercrab::error::{CoeAbortCode, MailboxError};
    let object = |s: u8| format!("{SM_OUTPUT_PARAMETER:#06x}:{s:02x}");
    let supported = match sd
        .sdo_read::<u16>(SM_OUTPUT_PARAMETER, sub::SYNC_MODES_SUPPORTED)
        .await
    {
        Ok(v) => v,
        Err(Error::Mailbox(MailboxError::Aborted {
            code: CoeAbortCode::NotFound | CoeAbortCode::SubIndexNotFound,
            ..
        })) => return Ok(()),
        Err(source) => {
            return Err(configure_err(axis, cfg, "sync modes supported", object(4))(
                source,
            ));
        }
    };
    if !dc::sync_mode_supported(supported, sync_mode::DC_SYNC0) {
        return Err(BringUpError::DcUnsupported {
            axis,
            joint: cfg.joint.clone(),
            vendor: cfg.vendor_id,
            product: cfg.product_code,
            supported,
        });
    }
    let min_ns = sd
        .sdo_read::<u32>(SM_OUTPUT_PARAMETER, sub::MIN_CYCLE_TIME)
        .await
        .map_err(configure_err(axis, cfg, "minimum cycle time", object(5)))?;
    if period_ns < u64::from(min_ns) {
        return Err(BringUpError::CycleTooShort {
            axis,
            joint: cfg.joint.clone(),
            vendor: cfg.vendor_id,
            product: cfg.product_code,
            cycle_us: (period_ns / 1000) as u32,
            min_ns,
        });
    }
    let cycle_ns = u32::try_from(period_ns).unwrap_or(u32::MAX);
    sd.sdo_write(SM_OUTPUT_PARAMETER, sub::SYNC_MODE, sync_mode::DC_SYNC0)
        .await
        .map_err(configure_err(axis, cfg, "sync mode DC SYNC0", object(1)))?;
    sd.sdo_write(SM_OUTPUT_PARAMETER, sub::CYCLE_TIME, cycle_ns)
        .await
        .map_err(configure_err(axis, cfg, "cycle time", object(2)))?;
    for (s, r) in [
        (
            sub::SYNC_MODE,
            sd.sdo_write(SM_INPUT_PARAMETER, sub::SYNC_MODE, sync_mode::DC_SYNC0)
                .await,
        ),
        (
            sub::CYCLE_TIME,
            sd.sdo_write(SM_INPUT_PARAMETER, sub::CYCLE_TIME, cycle_ns)
                .await,
        ),
    ] {
        if let Err(e) = r {
            tracing::warn!(
                "axis {axis} (joint {}): {SM_INPUT_PARAMETER:#06x}:{s:02x} not written ({e}); the drive keeps its own",
                cfg.joint
            );
        }
    }
    Ok(())
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
            codes::DC_CONFIG,
        ] {
            assert!(c > 0xFFFF);
        }
    }
}
