//! The STM32 board's analog stream ([`Stream`]): TIM6, DAC1, ADC1 and ADC2 on DMA1.
//!
//! ```text
//! TIM6 update @ 10 kHz ──TRGO──┬─> DAC1 CH1 (PA4) ← DMA1 CH3 ← DAC_BUF [2 × 25] (circular)
//!                              ├─> ADC1 IN1 (PA0, sense current)  → DMA1 CH1 → ring [2 × 25]
//!                              └─> ADC2 IN2 (PA1, drive monitor)  → DMA1 CH2 → ring [2 × 25]
//! ```
//!
//! ADC1 and ADC2 convert on the same TIM6_TRGO rising edge, with the same kernel clock, sample
//! time and resolution, so the current and the drive monitor are sampled at the same instant.
//! They run as two independent ADCs rather than in the dual regular-simultaneous mode: embassy
//! 0.6 writes ADC_CCR.DUAL after enabling ADC1, where RM0440 allows the field to be written
//! only with both ADCs disabled (docs/bringup.md, row 5e). The DMA1 CH1 half/full-transfer interrupt
//! (ADC1's ring) is the RTIC `sample` task; it runs embassy's DMA handler for that channel
//! itself ([`Stream::capture`]).
//!
//! DMA transfer errors (TEIF on any of the board's six DMA1 channels) are counted and cleared
//! before embassy's DMA handler runs (embassy 0.6 panics on TEIF); DAC DMA underruns (DMAUDR1;
//! embassy has no check) are read every batch. Either makes [`Stream::late`] true, is counted in
//! [`stream_faults`] and stops TIM6, so readings stall rather than run on without drive: after
//! a transfer error they end as `dma_error` (`Failure::of_stall`), after an underrun as
//! `drive_fault`.

use crate::engine::{SampleEngine, BATCH};
use crate::hal::{AdcFrame, FrontEndScale};
use crate::units::{AdcCode, DacCode};
use core::ptr::{addr_of, addr_of_mut};
use core::sync::atomic::{AtomicU32, Ordering};
use embassy_stm32::adc::{Adc, AdcChannel, AdcConfig, Exten, RingBufferedAdc, SampleTime};
use embassy_stm32::dac::{DacChannel, Mode};
use embassy_stm32::interrupt::typelevel::Handler;
use embassy_stm32::mode::Async;
use embassy_stm32::peripherals::{ADC1, ADC2, DMA1_CH1, TIM6};
use embassy_stm32::timer::low_level::{RoundTo, Timer};
use embassy_stm32::{dma, interrupt, pac, peripherals, Peri};

use super::clocks::{HCLK_HZ, TIM6_CLOCK_HZ};
use super::interrupts::{DmaFaults, Irqs};
use super::reset::record;
use super::{elapsed, spin_until, stamp, BootError, SAMPLE_RATE_HZ, SCALE, SYSCLK_HZ};

static DAC_UNDERRUNS: AtomicU32 = AtomicU32::new(0);

/// Hardware faults of the sample stream since boot. Either ends the stream (the DMA disables
/// the channel, the DAC stops its requests), and the driver then stops TIM6: after a non-zero
/// count the readings stall until reset.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StreamFaults {
    /// DMA1 transfer errors (TEIF) on channels 1–6 (ADC1, ADC2, DAC1, LPUART1 RX and TX, the
    /// DAC driver's unused channel): any of them stops the stream.
    pub dma_transfer_errors: u32,
    /// DAC1 channel 1 DMA underruns (DMAUDR1).
    pub dac_underruns: u32,
}

/// The stream's hardware fault counts (readable from any task).
pub fn stream_faults() -> StreamFaults {
    StreamFaults {
        dma_transfer_errors: crate::counters::DMA_ERRORS.load(Ordering::Relaxed),
        dac_underruns: DAC_UNDERRUNS.load(Ordering::Relaxed),
    }
}

/// The second ADC's last sample of a batch, after the first ADC's DMA interrupt: both convert
/// on the same trigger, so it is there within a few bus cycles; 2 000 cycles (12 µs) of margin.
const ADC_PAIR_TIMEOUT: u32 = 2_000;
/// One batch period in core cycles (2.5 ms).
const BATCH_CYCLES: u32 = SYSCLK_HZ / SAMPLE_RATE_HZ * BATCH as u32;

// Two DMA half-buffers: the pipeline of `reading::PIPELINE_BATCHES` that the host's simulated
// board models too.
const _: () = assert!(crate::engine::PIPELINE_BATCHES == 2);

/// DMA buffers: the DMA owns them once started; the interrupt touches only the halves the DMA
/// has just left: it refills the DAC's and reads the ADC rings' ([`read_rings`]).
static mut DAC_BUF: [DacCode; 2 * BATCH] = [DacCode::MID; 2 * BATCH];
static mut ADC1_RING: [u16; 2 * BATCH] = [0; 2 * BATCH];
static mut ADC2_RING: [u16; 2 * BATCH] = [0; 2 * BATCH];

/// DMA1 CH3, the DAC's channel, borrowed by its circular transfer for the life of the image.
static mut DAC_DMA: Option<dma::Channel<'static>> = None;

/// The converters of the stream (absent when a boot error kept them from being set up).
pub(super) struct Converters {
    adc1: RingBufferedAdc<'static, ADC1>,
    adc2: RingBufferedAdc<'static, ADC2>,
    tim: Timer<'static, TIM6>,
    /// Kept for its `Drop` (which would disable the channel); its DMA is [`DAC_DMA`].
    _dac: DacChannel<'static, Async>,
    /// DMAMUX request of DAC1 channel 1.
    dac_request: dma::Request,
    /// The DAC's circular transfer, once started.
    dac_transfer: Option<dma::Transfer<'static>>,
}

/// The DAC/ADC sample stream over TIM6, DAC1, ADC1, ADC2 and three DMA1 channels.
pub struct Stream {
    hw: Option<Converters>,
    frames: [AdcFrame; BATCH],
    current: [u16; BATCH],
    monitor: [u16; BATCH],
    /// [`stamp`] of the last batch (`None` before the first).
    last: Option<u32>,
    started: u32,
    late_seen: bool,
    fault_seen: bool,
    faults: StreamFaults,
    dac_underrun: bool,
}

impl Stream {
    /// The stream over `hw` (`None`: no converters, a boot error kept them from being set up).
    pub(super) fn new(hw: Option<Converters>) -> Self {
        Self {
            hw,
            frames: [AdcFrame::default(); BATCH],
            current: [0; BATCH],
            monitor: [0; BATCH],
            last: None,
            started: 0,
            late_seen: false,
            fault_seen: false,
            faults: StreamFaults::default(),
            dac_underrun: false,
        }
    }

    /// Converter scale of this board.
    pub fn scale(&self) -> FrontEndScale {
        SCALE
    }

    /// Prefill both DAC halves from `engine`, start the DAC's circular DMA and the ADC rings,
    /// then the trigger timer. Called once from `init` with interrupts disabled. If the DAC's
    /// transfer does not start, records [`BootError::DacStart`] and leaves the timer stopped
    /// (no batches, readings stall).
    pub fn start(&mut self, engine: &mut SampleEngine) {
        // SAFETY: init context, no DMA runs yet; the buffer is reached only through this
        // pointer now and, once the DMA runs, only the half it has left (`capture`).
        let dac_buf = unsafe { &mut *addr_of_mut!(DAC_BUF) };
        for half in dac_buf.chunks_exact_mut(BATCH) {
            engine.generate(half);
        }
        let Some(hw) = self.hw.as_mut() else {
            return;
        };
        // The DAC's circular DMA, DAC_BUF → DHR12R1, half-words read and written as words
        // (zero-extended by the DMA): embassy's `DacChannel::write` programs 16-bit peripheral
        // writes, which the G4's DAC answers with a bus error (RM0440 22, DAC: its registers take word
        // accesses only; embassy issue #2783, fixed after 0.6).
        // SAFETY: `DAC_DMA` was filled by `converters` and is used only here; the buffer is
        // static; the DMA reads it for ever while `capture` writes the half the DMA has left.
        let mut options = dma::TransferOptions::default();
        options.circular = true;
        options.half_transfer_ir = false;
        options.complete_transfer_ir = false;
        let transfer = unsafe {
            (*addr_of_mut!(DAC_DMA)).as_mut().map(|ch| {
                ch.write_raw::<u16, u32>(
                    hw.dac_request,
                    core::ptr::slice_from_raw_parts(addr_of!(DAC_BUF) as *const u16, 2 * BATCH),
                    pac::DAC1.dhr12r(0).as_ptr() as *mut u32,
                    options,
                )
            })
        };
        let Some(transfer) = transfer else {
            record(BootError::DacStart);
            return;
        };
        hw.dac_transfer = Some(transfer);
        // The rings (DMA and ADSTART) before the trigger: every TIM6 update from the first on
        // plays one DAC code and converts one sample on each ADC.
        hw.adc1.start();
        hw.adc2.start();
        // Gap: the DMA writes DHR12R1 only after the first trigger's request, so the first
        // trigger would move DHR's reset value 0 — a full-scale negative drive sample — to the
        // output (RM0440 22, DAC: with TEN1, DHR goes to DOR at the trigger; found by the
        // emulated board's rule check, emu/). RAW 13/17: DAC_DHR12R1 = mid-scale (no drive)
        // before the timer runs, a word write as the DAC requires.
        pac::DAC1.dhr12r(0).write(|w| w.set_dhr(DacCode::MID.0));
        hw.tim.start();
    }

    /// Acknowledge the DMA half/full-transfer interrupt of ADC1's ring; returns the ADC frames
    /// of the batch just captured and the DAC half just played (to refill). Counts DMA
    /// transfer errors and DAC underruns ([`stream_faults`]); a batch that saw one is late.
    pub fn capture(&mut self) -> (&[AdcFrame], &mut [DacCode]) {
        let now = stamp();
        // SAFETY: the DMA1_CH1 vector is this task's; embassy's handler for the channel (half
        // and full transfer of ADC1's ring, waker) runs here, after the transfer-error check.
        unsafe {
            <DmaFaults as Handler<interrupt::typelevel::DMA1_CHANNEL1>>::on_interrupt();
            <dma::InterruptHandler<DMA1_CH1> as Handler<interrupt::typelevel::DMA1_CHANNEL1>>::on_interrupt();
        }
        // A half that went by unserviced shows in the time since the last batch.
        self.late_seen = self
            .last
            .is_some_and(|t| now.wrapping_sub(t) > BATCH_CYCLES + BATCH_CYCLES / 2);
        self.last = Some(now);
        self.started = now;
        // The DAC half just played is the one its DMA is not in ([`completed_half`] of the
        // channel's remaining count). Both DMA streams run off the same trigger, so it is the
        // half of the ADC batch just captured; the DAC's output register holds the last sample
        // of that half already (it is fetched one trigger ahead), so the whole half can be
        // refilled.
        let h = self
            .hw
            .as_ref()
            .and_then(|hw| hw.dac_transfer.as_ref())
            .map_or(0, |t| completed_half(t.get_remaining_transfers()));

        // Gap: embassy 0.6's DAC driver has no underrun check: DAC_SR.DMAUDR1 (RM0440 22, DAC:
        // "DMA underrun"), read through [`dac_sr`]. Not cleared: the stream stops on
        // the first underrun, which is counted once.
        if !self.dac_underrun && self.hw.is_some() && dac_sr().dmaudr(0) {
            self.dac_underrun = true;
            DAC_UNDERRUNS.fetch_add(1, Ordering::Relaxed);
        }
        let faults = stream_faults();
        self.fault_seen = faults != self.faults;
        self.faults = faults;
        match self.hw.as_mut() {
            // Either fault ends the stream as a whole (a disabled DMA channel, a DAC that no
            // longer requests data): stop the trigger, so the measurement task's readings end
            // as `stalled` rather than run on with a dead drive or stale samples.
            Some(hw) if self.fault_seen => hw.tim.stop(),
            Some(_) => {
                if !read_rings(&mut self.current, &mut self.monitor) {
                    self.late_seen = true;
                }
            }
            None => self.late_seen = true,
        }
        for ((f, &i), &v) in self.frames.iter_mut().zip(&self.current).zip(&self.monitor) {
            *f = AdcFrame {
                current: AdcCode(i),
                monitor: AdcCode(v),
            };
        }
        // SAFETY: the DAC's DMA has left half `h` (it is in the other half) and comes back to it
        // only after the other half completes.
        let dac = unsafe {
            core::slice::from_raw_parts_mut(
                (addr_of_mut!(DAC_BUF) as *mut DacCode).add(h * BATCH),
                BATCH,
            )
        };
        (&self.frames, dac)
    }

    /// True when the handler was late: a half went by unserviced, or the handler ran longer
    /// than a batch (the next half completed before it finished) — or the batch saw a DMA
    /// transfer error or DAC underrun (its data are stale; [`stream_faults`] tells them apart).
    pub fn late(&self) -> bool {
        self.late_seen || self.fault_seen || elapsed(self.started) >= BATCH_CYCLES
    }
}

/// DMA1's channels of the ADC rings (channel `n + 1` is `ch(n)`): CH1 ADC1, CH2 ADC2.
const ADC1_DMA: usize = 0;
const ADC2_DMA: usize = 1;

/// The half of a ring of 2 × [`BATCH`] that its DMA channel has completed last, from the
/// transfers it has remaining (DMA_CNDTRx, RM0440 12: it counts down from 2 × BATCH and reloads
/// after the last): `2·BATCH ..= BATCH + 1` is the channel writing half 0, so half 1 is the one
/// completed; `BATCH ..= 1` is half 1 being written, half 0 completed.
const fn completed_half(remaining: u32) -> usize {
    if remaining as usize > BATCH {
        1
    } else {
        0
    }
}

/// DMA_CNDTRx of DMA1 channel `ch + 1` (RM0440 12): the transfers it has remaining.
fn dma_remaining(ch: usize) -> u32 {
    // RAW 17/17: DMA1 CNDTRx read. Gap: embassy 0.6's ring buffer reads it only inside its
    // own copy (`read_latest`, a modulo per sample).
    pac::DMA1.ch(ch).ndtr().read().ndt() as u32
}

/// Copy the half of `ring` the DMA has completed last (`half`) into `out`.
fn copy_half(ring: *const [u16; 2 * BATCH], half: usize, out: &mut [u16; BATCH]) {
    // SAFETY: `half` is the half the channel has left (it writes the other one) and comes back
    // to only after the other completes, a batch period away; the read is volatile, as the
    // DMA writes the ring behind the compiler's back.
    let src = unsafe { (ring as *const u16).add((half & 1) * BATCH) };
    for (k, o) in out.iter_mut().enumerate() {
        // SAFETY: `k < BATCH`, within the half.
        *o = unsafe { core::ptr::read_volatile(src.add(k)) };
    }
}

/// Read the batch just captured from both ADC rings: the half ADC1's channel has completed
/// (its half/full-transfer interrupt is the sample task) into `current`, the same half of
/// ADC2's ring into `monitor` once ADC2's channel has completed it too — both convert on the
/// same trigger, so its last sample is there within a few bus cycles; waited for at most
/// [`ADC_PAIR_TIMEOUT`]. False when it did not come (the batch is late). ADC2's channel's
/// handler runs here ([`sync_adc2_dma`]), as it did in embassy's ring read.
fn read_rings(current: &mut [u16; BATCH], monitor: &mut [u16; BATCH]) -> bool {
    let h = completed_half(dma_remaining(ADC1_DMA));
    core::sync::atomic::fence(Ordering::Acquire);
    copy_half(addr_of!(ADC1_RING), h, current);
    let paired = spin_until(ADC_PAIR_TIMEOUT, || {
        completed_half(dma_remaining(ADC2_DMA)) == h
    });
    sync_adc2_dma();
    core::sync::atomic::fence(Ordering::Acquire);
    copy_half(addr_of!(ADC2_RING), h, monitor);
    paired
}

/// embassy's handler for ADC2's DMA channel (DMA1 CH2), run from the sample task when it
/// reads that ring ([`read_rings`]): it acknowledges the half or full transfer and counts the
/// completed cycle, as the channel's own interrupt would (which then finds nothing to do).
/// Transfer errors are counted first ([`DmaFaults`]), as on the vector.
fn sync_adc2_dma() {
    // SAFETY: the same handlers the DMA1_CHANNEL2 vector runs (`Irqs`); that vector has the
    // sample task's priority, so the two never interleave.
    unsafe {
        <DmaFaults as Handler<interrupt::typelevel::DMA1_CHANNEL2>>::on_interrupt();
        <dma::InterruptHandler<peripherals::DMA1_CH2> as Handler<
            interrupt::typelevel::DMA1_CHANNEL2,
        >>::on_interrupt();
    }
}

/// is to be checked), at 170 MHz.
const DAC_TRIM_CYCLES: u32 = SYSCLK_HZ / 20_000;

/// DAC_MCR.HFSEL, the DAC's high-frequency interface mode, for an AHB clock of `hclk_hz`
/// (RM0440 22, DAC: DAC_MCR): 00 up to 80 MHz, 01 above 80 MHz, 10 above 160 MHz.
const fn dac_hfsel(hclk_hz: u32) -> u8 {
    if hclk_hz > 160_000_000 {
        0b10
    } else if hclk_hz > 80_000_000 {
        0b01
    } else {
        0
    }
}

/// DAC_SR (RM0440 22, DAC: DAC_SR): CAL_FLAG1 for the calibration, DMAUDR1 for the
/// stream. Gap: embassy-stm32 0.6's DAC driver reads neither.
fn dac_sr() -> pac::dac::regs::Sr {
    // RAW 9/17: DAC_SR read.
    pac::DAC1.sr().read()
}

/// DAC_CR (RM0440 22, DAC: DAC_CR): CEN1 (calibration mode) and DMAEN1. Gap: embassy-stm32
/// 0.6 sets DMAEN1 only inside `DacChannel::write`, whose 16-bit DMA the G4's DAC refuses, and
/// has no calibration.
fn dac_cr(f: impl FnOnce(&mut pac::dac::regs::Cr)) {
    // RAW 10/17: DAC_CR modify.
    pac::DAC1.cr().modify(f);
}

/// Calibrate DAC1 channel 1's output buffer offset (RM0440 22, DAC: "DAC channel output
/// buffer calibration"): with the channel off and in normal buffered mode, CEN1 set, OTRIM1
/// stepped up from 0, tTRIM after each step, until CAL_FLAG1 reads 1 — the first trim at or
/// above the offset. 32 steps at most (1.6 ms); false if the flag never rose.
///
/// Gap: embassy-stm32 0.6's DAC driver has no calibration.
fn calibrate_dac() -> bool {
    dac_cr(|w| w.set_cen(0, true));
    let mut found = false;
    for trim in 0..32 {
        // RAW 11/17: DAC_CCR.OTRIM1 (RM0440 22, DAC: DAC_CCR); OTRIM2 (channel 2, unused)
        // written 0.
        pac::DAC1.ccr().write(|w| w.set_otrim(0, trim));
        cortex_m::asm::delay(DAC_TRIM_CYCLES);
        if dac_sr().cal_flag(0) {
            found = true;
            break;
        }
    }
    dac_cr(|w| w.set_cen(0, false));
    found
}

/// The peripherals of the sample stream.
pub(super) struct ConverterPins {
    pub(super) tim6: Peri<'static, TIM6>,
    pub(super) dac1: Peri<'static, peripherals::DAC1>,
    pub(super) dac_dma: Peri<'static, peripherals::DMA1_CH3>,
    /// Handed to `DacChannel::new_triggered`, which wants a DMA channel; never started.
    pub(super) dac_dma_unused: Peri<'static, peripherals::DMA1_CH5>,
    pub(super) pa4: Peri<'static, peripherals::PA4>,
    pub(super) adc1: Peri<'static, ADC1>,
    pub(super) adc1_dma: Peri<'static, DMA1_CH1>,
    pub(super) pa0: Peri<'static, peripherals::PA0>,
    pub(super) adc2: Peri<'static, ADC2>,
    pub(super) adc2_dma: Peri<'static, peripherals::DMA1_CH2>,
    pub(super) pa1: Peri<'static, peripherals::PA1>,
}

/// Set up TIM6 (10 kHz TRGO, stopped), DAC1 CH1 (triggered, calibrated, its DMA channel in
/// [`DAC_DMA`]) and the two ADC rings; [`Stream::start`] starts them.
pub(super) fn converters(p: ConverterPins) -> Converters {
    // TIM6: 10 kHz update, its update event as TRGO, not yet running. Its period in clocks of
    // the board's own TIM6_CLOCK_HZ: embassy's `set_frequency` would divide its record of the
    // timer clock, which is halved (clocks.rs).
    let tim = Timer::new(p.tim6);
    tim.set_period_clocks(u64::from(TIM6_CLOCK_HZ / SAMPLE_RATE_HZ), RoundTo::Faster);
    // Gap: embassy 0.6's low-level timer has no master-mode setter. RAW 7/17: TIM6_CR2.MMS =
    // update → TRGO (RM0440 "Basic timers (TIM6/TIM7)" chapter, TIMx_CR2;
    // its number unverified: docs/bringup.md).
    tim.regs_basic()
        .cr2()
        .modify(|w| w.set_mms(pac::timer::vals::Mms::UPDATE));
    tim.generate_update_event();

    // DAC1 CH1 on PA4, normal mode with the output buffer, triggered by TIM6_TRGO, fed by DMA1
    // CH3 (our own transfer, started in `Stream::start`: embassy's `DacChannel::write` programs
    // 16-bit peripheral writes, which the G4's DAC refuses).
    let dac_request =
        embassy_stm32::dac::Dma::<peripherals::DAC1, embassy_stm32::dac::Ch1>::request(&*p.dac_dma);
    let mut dac = DacChannel::new_triggered(
        p.dac1,
        p.dac_dma_unused,
        embassy_stm32::triggers::TIM6_TRGO,
        Irqs,
        p.pa4,
    );
    // embassy's `new_triggered` selects the trigger (TSEL1) and enables the channel but never
    // sets TEN1, without which the DAC neither waits for TIM6 nor requests DMA (RM0440 22, DAC:
    // "DAC trigger selection", "DMA requests"): `set_mode` turns EN1 off (TEN1 and the
    // calibration want the channel off), TEN1 is set, the buffer calibrated, EN1 and DMAEN1
    // set. No trigger comes before TIM6 starts, so no DMA request before the transfer runs.
    dac.set_mode(Mode::NormalExternalBuffered);
    dac.set_triggering(true);
    // Gap: embassy sets DAC_MCR.HFSEL from its record of HCLK, which is halved (clocks.rs): the
    // mode for 80–160 MHz where HCLK is 170 MHz. RAW 16/17: DAC_MCR.HFSEL from the real HCLK
    // ([`dac_hfsel`]), with the channel off.
    pac::DAC1.mcr().modify(|w| w.set_hfsel(dac_hfsel(HCLK_HZ)));
    // A DAC whose calibration never settles is not trusted with the drive: the stream is not
    // started (readings end as `stalled`).
    let calibrated = calibrate_dac();
    if calibrated {
        dac.enable();
        dac_cr(|w| w.set_dmaen(0, true));
        // SAFETY: init context; `Stream::start` is the only other user of `DAC_DMA`.
        unsafe { *addr_of_mut!(DAC_DMA) = Some(dma::Channel::new(p.dac_dma, Irqs)) };
    } else {
        record(BootError::DacCalibration);
    }

    // ADC1 (current, PA0 = IN1) and ADC2 (monitor, PA1 = IN2): calibrated (single-ended and
    // differential), 20 µs before ADEN, by `Adc::new`; kernel clock SYSCLK / 4 = 42.5 MHz.
    let adc1 = Adc::new(p.adc1, AdcConfig::default());
    let adc2 = Adc::new(p.adc2, AdcConfig::default());
    // SAFETY: init context, before any DMA runs; the rings are handed to embassy for good.
    let (ring1, ring2) = unsafe { (&mut *addr_of_mut!(ADC1_RING), &mut *addr_of_mut!(ADC2_RING)) };
    // Each converts its one channel (47.5 cycles' sampling) on every TIM6 update, into its DMA
    // ring.
    macro_rules! on_tim6 {
        ($adc:expr, $dma:expr, $ring:expr, $pin:expr) => {
            $adc.into_ring_buffered(
                $dma,
                $ring,
                Irqs,
                [($pin.degrade_adc(), SampleTime::CYCLES47_5)].into_iter(),
                embassy_stm32::triggers::TIM6_TRGO,
                Exten::RISING_EDGE,
            )
        };
    }
    let adc1 = on_tim6!(adc1, p.adc1_dma, ring1, p.pa0);
    let adc2 = on_tim6!(adc2, p.adc2_dma, ring2, p.pa1);
    Converters {
        adc1,
        adc2,
        tim,
        _dac: dac,
        dac_request,
        dac_transfer: None,
    }
}
