//! The lifecycle the framework holds around any [`ActuatorBackend`] (ros2_control's
//! `hardware_interface` states): Unconfigured → Inactive → Active, Fault on any error
//! until a reset (Fault → Inactive). Each backend hook is called only from the state it
//! belongs to, so backends carry no state guards; a [`Fault`] returned by any call moves
//! to Fault, keeps the fault for the status and log, and calls `on_error` once.

use microrobot_messages::{LifecycleHook, LifecycleState};
use microrobot_model::JointVector;

use crate::backend::{ActuatorBackend, Fault, Measured};

/// One of a backend's lifecycle hooks.
type HookFn<B> = fn(&mut B) -> Result<(), Fault>;

/// A backend and its lifecycle state.
#[derive(Debug, Clone)]
pub struct Lifecycle<B> {
    backend: B,
    state: LifecycleState,
    fault: Option<Fault>,
    faults: u64,
    /// Wall time spent inside hooks, not yet taken.
    hook_ns: u64,
}

impl<B: ActuatorBackend> Lifecycle<B> {
    /// `backend`, not configured yet.
    pub fn new(backend: B) -> Self {
        Self {
            backend,
            state: LifecycleState::Unconfigured,
            fault: None,
            faults: 0,
            hook_ns: 0,
        }
    }

    /// The backend.
    pub fn backend(&self) -> &B {
        &self.backend
    }

    /// The backend, mutable (tests, simulation set-up).
    pub fn backend_mut(&mut self) -> &mut B {
        &mut self.backend
    }

    /// Wall time spent inside the lifecycle hooks (configure, activate, deactivate,
    /// reset) since the last call (ns).
    pub fn take_hook_ns(&mut self) -> u64 {
        std::mem::take(&mut self.hook_ns)
    }

    /// The current state.
    pub fn state(&self) -> LifecycleState {
        self.state
    }

    /// The last fault (kept after a reset, for the status).
    pub fn last_fault(&self) -> Option<&Fault> {
        self.fault.as_ref()
    }

    /// Faults entered so far.
    pub fn faults(&self) -> u64 {
        self.faults
    }

    fn enter_fault(&mut self, f: Fault) {
        self.faults += 1;
        self.state = LifecycleState::Fault;
        self.backend.on_error(&f);
        self.fault = Some(f);
    }

    fn transition(
        &mut self,
        from: LifecycleState,
        to: LifecycleState,
        (name, hook): (LifecycleHook, HookFn<B>),
        announce: &mut dyn FnMut(LifecycleHook),
    ) -> bool {
        if self.state != from {
            return false;
        }
        announce(name);
        let t0 = std::time::Instant::now();
        let r = hook(&mut self.backend);
        let took = u64::try_from(t0.elapsed().as_nanos()).unwrap_or(u64::MAX);
        self.hook_ns = self.hook_ns.saturating_add(took);
        match r {
            Ok(()) => {
                self.state = to;
                true
            }
            Err(f) => {
                self.enter_fault(f);
                false
            }
        }
    }

    /// Unconfigured → Inactive (`on_configure`). Returns the fault if it failed.
    pub fn configure(&mut self) -> Result<(), Fault> {
        if self.transition(
            LifecycleState::Unconfigured,
            LifecycleState::Inactive,
            (LifecycleHook::Configure, B::on_configure),
            &mut |_| {},
        ) {
            Ok(())
        } else {
            Err(self
                .fault
                .clone()
                .unwrap_or_else(|| Fault::drive(0, "configure is only allowed while unconfigured")))
        }
    }

    /// Inactive → Active (`on_activate`); whether it happened. `announce` is called just
    /// before the hook runs (not at all when it does not).
    pub fn activate(&mut self, announce: &mut dyn FnMut(LifecycleHook)) -> bool {
        self.transition(
            LifecycleState::Inactive,
            LifecycleState::Active,
            (LifecycleHook::Activate, B::on_activate),
            announce,
        )
    }

    /// Active → Inactive (`on_deactivate`); whether it happened.
    pub fn deactivate(&mut self) -> bool {
        self.transition(
            LifecycleState::Active,
            LifecycleState::Inactive,
            (LifecycleHook::Deactivate, B::on_deactivate),
            &mut |_| {},
        )
    }

    /// Fault → Inactive (`on_reset`); whether it happened. `announce` is called just
    /// before the hook runs (not at all when it does not).
    pub fn reset_fault(&mut self, announce: &mut dyn FnMut(LifecycleHook)) -> bool {
        self.transition(
            LifecycleState::Fault,
            LifecycleState::Inactive,
            (LifecycleHook::Reset, B::on_reset),
            announce,
        )
    }

    /// Writes `tau` while Active; false if not active or the backend faulted.
    pub fn write(&mut self, now_ns: u64, period_s: f64, tau: &JointVector) -> bool {
        if self.state != LifecycleState::Active {
            return false;
        }
        match self.backend.write(now_ns, period_s, tau) {
            Ok(()) => true,
            Err(f) => {
                self.enter_fault(f);
                false
            }
        }
    }

    /// Reads the measured state (not while Unconfigured or Finalized); `None` if the
    /// backend faulted.
    pub fn read(&mut self, now_ns: u64) -> Option<Measured> {
        if matches!(
            self.state,
            LifecycleState::Unconfigured | LifecycleState::Finalized
        ) {
            return None;
        }
        match self.backend.read(now_ns) {
            Ok(m) => Some(m),
            Err(f) => {
                if self.state != LifecycleState::Fault {
                    self.enter_fault(f);
                }
                None
            }
        }
    }

    /// The process stops (after [`Lifecycle::deactivate`] and the last read):
    /// `on_shutdown`, then Finalized. Only once.
    pub fn finalize(&mut self) {
        if self.state != LifecycleState::Finalized {
            self.backend.on_shutdown();
            self.state = LifecycleState::Finalized;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Records the hooks called; faults on demand.
    #[derive(Default)]
    struct Probe {
        calls: Vec<&'static str>,
        fail_write: bool,
    }

    impl ActuatorBackend for Probe {
        fn dof(&self) -> usize {
            1
        }
        fn on_configure(&mut self) -> Result<(), Fault> {
            self.calls.push("configure");
            Ok(())
        }
        fn on_activate(&mut self) -> Result<(), Fault> {
            self.calls.push("activate");
            Ok(())
        }
        fn on_deactivate(&mut self) -> Result<(), Fault> {
            self.calls.push("deactivate");
            Ok(())
        }
        fn on_error(&mut self, _: &Fault) {
            self.calls.push("error");
        }
        fn on_reset(&mut self) -> Result<(), Fault> {
            self.calls.push("reset");
            Ok(())
        }
        fn on_shutdown(&mut self) {
            self.calls.push("shutdown");
        }
        fn write(&mut self, _: u64, _: f64, _: &JointVector) -> Result<(), Fault> {
            self.calls.push("write");
            if self.fail_write {
                return Err(Fault::joint(0, 0x7500, "communication lost"));
            }
            Ok(())
        }
        fn read(&mut self, _: u64) -> Result<Measured, Fault> {
            Ok(Measured::default())
        }
    }

    #[test]
    fn hooks_run_only_in_their_state_and_a_fault_latches_until_reset() {
        let mut l = Lifecycle::new(Probe::default());
        assert!(l.read(0).is_none(), "no read before configure");
        assert!(!l.activate(&mut |_| {}), "no activate before configure");
        assert!(!l.write(0, 1e-3, &JointVector::zeros()));
        l.configure().unwrap();
        assert!(l.configure().is_err(), "configure once");
        assert!(!l.write(0, 1e-3, &JointVector::zeros()), "inactive");
        assert!(l.activate(&mut |_| {}));
        assert!(l.write(0, 1e-3, &JointVector::zeros()));
        l.backend_mut().fail_write = true;
        assert!(!l.write(0, 1e-3, &JointVector::zeros()));
        assert_eq!(l.state(), LifecycleState::Fault);
        let f = l.last_fault().unwrap();
        assert_eq!((f.joint, f.code), (Some(0), 0x7500));
        assert_eq!(f.to_string(), "joint 1: communication lost (code 0x7500)");
        assert!(
            !l.write(0, 1e-3, &JointVector::zeros()),
            "no write in Fault"
        );
        assert!(!l.activate(&mut |_| {}), "no activate in Fault");
        assert!(l.reset_fault(&mut |_| {}));
        assert_eq!(l.state(), LifecycleState::Inactive);
        l.finalize();
        l.finalize();
        assert!(l.read(0).is_none(), "no read after finalize");
        assert_eq!(
            l.backend().calls,
            [
                "configure",
                "activate",
                "write",
                "write",
                "error",
                "reset",
                "shutdown"
            ]
        );
        assert_eq!(l.faults(), 1);
    }
}
