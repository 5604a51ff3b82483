"""The prose of ``rfi_monitor_speed.py``'s stage section in docs/rfi_monitor/speed.md (issue 26 item 2): what each
round of speed work did and measured, written below the regenerated tables (kept apart: the script stays under
700 lines)."""

ISSUE26_NOTES = """Issue 26 item 2, fifth round (2026-12-08: the ridge stages, the block-end law, the other stages and
the integration, by four workers in parallel; one behaviour change): **the goal is not met; the full analysis went from
0.6-1.0x to 0.9-1.7x real time.** The run above: 1 run of all 9 cases (``--runs 1``), the machine otherwise nearly
idle (load average 0.3-1.2 on 2 cores). At 38.192 MS/s the full analysis costs 8.8 (acquisition), 5.3 (tracking) and
6.8 (switch) bare STFTs of its block against 11.4, 10.1 and 9.5 for 93ea8b7 in the same run (goal: about 3-4),
0.92 / 1.69 / 1.33x real time, p99 at most 2.8 ms; at 10 MS/s complex 14.7 / 11.8 / 13.4 (25.1 / 18.8 / 21.4 before),
0.96-1.17x; at 24 MS/s real 11.0 / 8.5 / 9.7 (16.5 / 13.2 / 14.3 before), 1.11-1.47x. Now over before in the same
run (mean ms): 0.76 / 0.48 / 0.72 at 38.192 MS/s, 0.58 / 0.65 / 0.57 at 10 MS/s complex, 0.60 / 0.58 / 0.68 at
24 MS/s real (the fourth round's run: 0.79 / 0.90 / 0.86, 0.71 / 0.73 / 0.77, 0.79 / 0.87 / 0.92). A run of the same
tree a minute earlier read 7.6 / 5.3 / 6.9 at 38.192 MS/s (1.20 / 1.67 / 1.32x), 14.9 / 11.0 / 13.0 and
10.2 / 8.0 / 9.5: the acquisition's figure moves most between runs (its integration decisions land on few blocks).

Found: the earlier rounds timed compiled kernels repeatedly on ONE array, which trains the branch predictor on that
array's comparisons: a selection whose branches depend on the data read 3-4x faster than inside the pipeline (the
noise level's Floyd-Rivest selection of the fourth round: 40 us on one 511 x 33 spectrogram timed again and again,
170-190 us a call on the pipeline's successive blocks, 1.3-1.8 bare STFTs of a 38.192 MS/s tracking block). Timed
over 40-120 different arrays captured from the pipeline, numpy's SIMD sort beat it on every shape the monitor uses.
Every figure of this round is timed that way or inside the pipeline.

Done this round (src/rfi_monitor):

* Ridge stages (bit-identical: split_reference.py --check): the noise level's lower quantile by numpy's sort of the
  transposed copy below 768 frames and, from 768 frames on, a compiled histogram selection (order keys of the float32
  bits, passes along the rows without branches on the data, the k-th value among the few of its bucket by rank
  counting); per call 511 x 33 185 -> 38 us, 255 x 65 209 -> 38, 155 x 128 217 -> 53, 1249 x 16 170 -> 62, 2047 x 5
  80 -> 41. The same bias in the smaller sorts: the 3-bin median across bins, the band edges' 2 % / 98 % points
  (``numpy_kernels.quantile_pair``: only the few smallest and largest values kept) and the phase profiles' per-bin
  sorts (rank counting up to 16 values, insertion sort to 64), each replaced.
* The block-end law (bit-identical): its fit, read at the block end, leverage and period drift in one compiled kernel
  (``sweep_law.law_at_block_end``): ``ridge._block_end_frequency`` 0.17-0.20 -> 0.03-0.05 ms a block.
* The other stages: the constant-envelope J/N of a real block over its last 4,096 samples instead of 8,192 (the one
  behaviour change: the Hilbert transform's two FFTs halve; J/N of the split reference's real chirp streams moved by
  a median 0.06 dB, at most 0.32 dB on a block; real_jammers.md's J/N medians unchanged, the 38.192 MS/s CW row's
  spread 0.1 dB wider; complex blocks keep 8,192: their moments need no FFT); the noise template's running median kept
  sorted as it slides (25 -> 5 us), the learned floor's medians without np.median (62 -> 15 us a quiet block), the
  estimate built without the frozen dataclass's per-field __init__, the spectral step's group powers in one kernel.
* The integration (bit-identical): the coarse comb's candidate lags as a compact int16 grid (0.2 instead of 0.9 MB
  read per tested sum) and its 240 best by a selection and a stable sort (per tested sum 170-210 -> 110-140 us); a
  block with a decision 11.9 -> 10.7 bare STFTs at 38.192 MS/s.

What is left (38.192 MS/s, bare STFTs, the table above): tracking: the ridge 3.1 (its STFT, frame ridges, noise
levels, period search, profiles), the Welch PSD and features 0.85, the envelope 0.5, the rest 0.7; acquisition: the
integration 3.4 (an added block costs about 6, measured without a cheaper exact form: the framing and FFT of its
2,386-frame 32-point STFT 1.3, the amplitudes' FFT 0.7 at the 4,320 points the comb's 1,789 lags need, the
1024-point Welch PSD 0.7, amplitudes and covariances 0.8), the ridge 2.1, Welch 0.85, the rest 1.2. The goal still
needs the behaviour changes measured in the rounds below (integration at hop L, one spectrum for the classifier's
features and the CW test, fewer window lengths per decision) or a lower ``integration_max_samples_per_s``, each a
loss of sensitivity or latency to weigh against sensitivity.md.

Issue 26 item 2, fourth round (2026-12-07, night: fewer calls at the small blocks, no behaviour
change): **the goal is not met, and the totals did not move beyond this machine's noise.** The run above: 1 run of all
9 cases (``--runs 1``), 8 workers sharing the 2 cores (load average 13 falling to 5 during the run, 16-18 during the
work). At 38.192 MS/s the full analysis costs 9.8 (acquisition), 8.6 (tracking) and 8.7 (switch) bare STFTs of its block
against 12.4, 9.6 and 10.1 for 93ea8b7 in the same run (goal: about 3-4), 0.70-0.87x real time; at 10 MS/s complex
18.7 / 14.2 / 17.9 (26.5 / 19.5 / 23.1 before), 0.59-0.85x; at 24 MS/s real 12.7 / 11.6 / 13.0 (16.1 / 13.3 / 14.1
before), 0.60-0.88x; p99 at most 3.6 ms. Now over before in the same run: 0.79 / 0.90 / 0.86, 0.71 / 0.73 / 0.77,
0.79 / 0.87 / 0.92, where the third round's run read 0.81 / 0.85 / 0.79, 0.71 / 0.70 / 0.90, 0.77 / 0.99 / 0.86: the
same within the +-10-15 % that one run carries. A first run of the same tree, started right after the edits, read
71.1 bare STFTs at 38.192 MS/s switch (mean 11.1 ms, p99 3.1 ms: one block of about 1.7 s, the switch-on block).
Found and fixed after the run: on a cold numba cache, the noise level's quantile from np.partition (a strided
column) compiled a second version of ``_noise_levels_kernel`` (1.1-1.6 s) on the first block that took that path
(presumably the whole 38.192 MS/s block at L = 128: 595 x 65 cells, above the new limit), a version warm_up no
longer compiled now that the shorter columns take the compiled selection; the quantile is made contiguous on both
paths (one version; the switch-on block on a cold cache 1,109 -> 13 ms, as at 60afe7c: 14 ms). The table above was
measured before that fix, which changes no value and no time on a warm cache.

Done this round (src/rfi_monitor: stft.py, classifier.py, spectral_autocorrelation.py, constant_envelope.py;
bit-identical: split_reference.py --check, all 900 fields of its 12 streams; real_jammers.md's table unchanged):
scipy's pocketfft binding called directly (as ``stft.fft_inplace`` already did for the ridge: ``rfft_rows``,
``irfft_rows``, ``irfft_real``; no scipy.fft dispatch, 5-15 us a call) in the classifier's Welch PSD, the
integration's spectral autocorrelation (its STFT, the amplitudes' rfft and the irfft) and the envelope's Hilbert
transform; the noise level's compiled selection (``column_order_statistic``) also below 768 frames up to 32,768
cells (155 x 128 at 10 MS/s acquisition: 60 vs 110 us for np.partition of the transposed copy; 255 x 65: 57 vs 77;
numpy kept above, where it won at 255 x 129, 154 vs 310 us); the window energy of the Parseval sum cached per frame
length (the bin frequencies were too, as read-only arrays, and are computed again: a read-only array is another type
to numba, which a kernel warmed with a writable one would compile again, for ~2 us). In bare STFTs, this run against
the third round's: welch + features 1.04 /
1.64 / 1.22 -> 0.92 / 1.55 / 1.00 (10 MS/s complex), 1.01 / 1.30 / 1.05 -> 0.77 / 1.10 / 0.90 (24 MS/s real);
integration 6.72 -> 6.02 (10 MS/s acquisition), 5.09 -> 3.73 (24 MS/s); envelope J/N 1.49 -> 1.16 (24 MS/s
tracking). In an A/B against the third round's tree (60afe7c, 2 runs alternated, load 16-18) the same stages moved
the same way (welch + features 1.71 -> 1.37, 1.19 -> 0.94, 1.20 -> 1.04; integration 6.61 -> 5.87; envelope
1.45 -> 1.14) and the totals by -7 to +4 %: noise. Measured and not done: a radix selection (histogram of the
float32 keys) and a sampled two-pivot filter for the long columns (1,249 x 16 at 10 MS/s tracking: 54 -> 46 us, the
selection proper is already ~2 ns a value; the column gather 15 us of it): not worth their code.

What remains at the small blocks (10 MS/s complex tracking, cProfile by thread time, 100 blocks, the loaded machine:
about 2.7 ms a block in all, 300 Python-level calls): the ridge 1.8 ms (its STFT of 1,249 16-point frames 0.2, the
noise levels 0.28 of which the selection 0.19, the frame ridges 0.21, the period search 0.25, the profiles, shape
and fold residuals 0.38, the block-end frequency 0.40 of which the saw-tooth law's fit and prediction interval in
sweep_law.py 0.29, another helper's file this round), the Welch PSD and features 0.44, the rest 0.5. Each stage is
already one or two compiled kernels; what is left per stage is its arithmetic on 1,249 frames x 16 bins and 5-30 us
of call overhead, so the goal needs fewer passes over the block, i.e. the behaviour changes listed below for the
third round (hop L instead of L / 2, a shared spectrum for the classifier and the CW statistic, the envelope over
fewer samples) or the ridge's own: its noise quantile, frame ridges and period phasor from one pass over a shared
spectrogram (the classifier's 256-point frames are 16 times the ridge's 16-point ones at 10 MS/s; one spectrogram
for both would change the ridge's time resolution or the classifier's frequency resolution).

Issue 26 item 2, third round (2026-12-07, evening: the stages outside the ridge; behaviour
changes allowed): **the goal is not met.** Its run (2 runs of all 9 cases, the machine otherwise running one
test process, load about 1-2 on 2 cores): at 38.192 MS/s the full analysis cost 10.0 (acquisition), 7.5 (tracking)
and 7.7 (switch) bare STFTs of its block against 12.3, 8.8 and 9.7 for 93ea8b7 in the same run (goal: about 3-4),
0.78-1.07x real time; at 10 MS/s complex 17.2 / 13.7 / 17.3 (24.2 / 19.5 / 19.3 before), 0.64-0.82x; at 24 MS/s real
13.1 / 12.5 / 12.5 (17.0 / 12.6 / 14.5 before), 0.86-0.98x; p99 at most 3.6 ms (goal <= 5 ms: met). The same tree in a
reduced run during the work (``--runs 1``, 5 of the 9 cases, load 15, the bare STFT itself 0.20-0.31 ms across the
children) read 8.5 / 6.1 / 6.3 at 38.192 MS/s against 9.6 / 8.7 / 8.2 before: the ratios carry about +-15-20 % between
runs; the ratio to 93ea8b7 in the same run (0.79-0.85 of its bare STFTs at 38.192 MS/s here) is the steadier figure.

Done this round (src/rfi_monitor: constant_envelope.py, cw_statistic.py, chirp_comb.py, integration.py):

* Constant-envelope J/N: the Hilbert transform by a real FFT and its inverse (``hilbert_transform``) instead of the
  complex inverse FFT of the doubled spectrum, the moments from x^2 + H(x)^2 in one compiled pass: per call 144-160
  -> 95 us (8,192 samples); the stage 1.41 -> 0.96 bare STFTs (38.192 MS/s tracking), 2.28 -> 1.54 (24 MS/s). The
  same J/N to 5e-13 dB (rounding; split_reference regenerated), real_jammers.md unchanged.
* The integration's decisions: the CW test's running median and scores in one kernel (per tested sum 38-87 -> 13-14
  us), the comb's coarse selection (argpartition, argsort, separation) and its fine comb with the best candidate's
  terms in two kernels (per sum 253-348 -> 185-199 us); a decision on a full window (4 sums) 1.81-1.95 -> 1.20-1.41
  ms, in one process, alternated. One change of behaviour: among equal coarse combs (flat plateaus of rounded lags)
  the shorter period is taken first, where numpy's partition left the order to its implementation; no field of
  split_reference's 12 streams moved, real_jammers.md and the integration tests unchanged.

What is left, and what the goal would need (38.192 MS/s quiet block, the reduced run, bare STFTs): ridge 2.3,
integration
2.7, the classifier's Welch PSD and features 0.9, spectral step 0.7, frame length 0.3, the rest 1.6. Without the ridge
(another round's) and the rest, the stages here would have to cost nothing to reach 4. The integration's cost is its
statistic: an added block (43 % of them at 38.192 MS/s under the 16.5 MS/s budget) pays 5-6 bare STFTs in the
spectral autocorrelation (its 2,386-frame 32-point STFT ~1, the 15 x 4,320-point FFT of the amplitudes ~1.5, the bin
covariances ~0.7, the amplitudes and lag terms the rest) and ~0.7 in the 1024-point Welch PSD. Measured and not
done, each a loss to weigh: (1) hop L instead of L / 2 halves the frames and the FFT lengths (47 instead of 96
us, 75 instead of 158 us), but Hann frames at hop L / 2 are nearly independent (complex correlation of white noise
0.19), so the comb's z for the same blocks falls by about sqrt 2: the same detection needs twice the blocks, the
trade that halving ``integration_max_samples_per_s`` already makes, at the same cost per frame;
(2) the CW statistic on the sum of the classifier's 256-point PSDs instead of its own 1024-point one would drop the
1024-point Welch PSD (~0.3 bare STFTs per 38.192 MS/s block, ~1 at 10 MS/s complex, where every block is added);
a tone at the reporting floor (the classifier's detect_jn_db, -6 dB) stays significant by orders of magnitude, but
the 31-bin running median would span a quarter of a real 256-bin band and no longer follow a 2 MHz pass band in a
19 MHz one: the smoothing width and the false alarms on the real clean captures would have to be derived again;
(3) the envelope moments over 4,096 samples instead of 8,192: ~0.5 bare STFTs per tracking block, their scatter
1.4 % instead of 1 % (the J/N column of real_jammers.md would scatter more); (4) decisions spread over blocks would
lower the p99 (a full-window decision, 1.2-1.4 ms, lands on one block), not the mean. The classifier's Welch PSD
(one 256-point Hann PSD of the block) is a bare STFT by construction: cheaper only shared with another stage's
spectrum, whose frame length and overlap differ (the ridge: L = 64-256 at hop L / 2 on the block's tail).

The second round (earlier the same day; its run, 2 runs of all 9 cases on a quieter machine, read 7.1-9.0 bare STFTs
at 38.192 MS/s, 0.82-1.01x real time; 10 MS/s complex 15.7-18.8, 0.74-0.86x; 24 MS/s real 12.1-13.7, 0.87-1.04x; at
the start of the day 9.2-10.0, 18.6-24.1 and 13.6-15.4; p99 <= 2.9 ms once the compiled functions are warmed up as
the node does; the cold first blocks of a stream cost 70-340 ms: numba loading its cache):

Where the time goes: four different spectrograms of every block, each with its own frame length, window and
overlap, and 100+ numpy calls of 2-20 us each. Quiet 38.192 MS/s block: the integration over blocks 34 % (its own
32-sample STFT at hop 16 of the whole block, 2,386 frames, about 1.5 bare STFTs; its 1024-point Welch PSD; the comb
decision every 10 ms of stamps, 1-2 ms each, which sets the p99), the ridge analysis 33 % (its STFT of the last 16,384
samples at hop L/2, noise levels, excess pass, periodicity FFT), the classifier's 256-point Welch PSD and features
11 %, the spectral-step test 6 %. Tracking block: the ridge 57 %, Welch 17 %, the constant-envelope J/N 15 % (the
analytic signal, an FFT of 8,192 samples). At 10 MS/s complex the block is small (10,000 samples) and the fixed cost
of the numpy calls dominates: 19-24 bare STFTs.

Done (bit-identical: every JammerEstimate field of 160-block streams at the three front ends, acquisition and
switch-on, equal to those of 93ea8b7; test_ridge_speed_equivalence.py passes): stft_power's framing, float32
conversion, window and |X|^2 compiled (no temporaries); the integration's fine comb summed from the candidate periods
directly (no lag and mask arrays of a few hundred candidates x 128 multiples) and its candidate separation compiled.
Gain 0-5 % of a block, within this machine's noise.

Done, the ridge analysis, second pass (bit-identical: split_reference.py --check, all 900 fields of its 12 streams;
real_jammers.md's table unchanged): the frame ridges' interpolation, presence flags and means fused into the excess
pass (two kernels and one np.log instead of ~15 numpy calls; the noise divisors, the complex phasor, the cos/sin tables
cached per bin count); phase_profiles in one kernel; scipy's pocketfft binding called directly for the STFT's FFT and
the period search's two FFTs (the same transforms to the bit, without scipy.fft's or numpy.fft's dispatch); the lower
noise quantile by a compiled selection on long columns (>= 768 frames: 1249 x 16 at 10 MS/s with 16-sample frames,
where np.partition took 115 us and the selection 48). The ridge stage in bare STFTs, the run above against the
previous one ('now' of each): 38.192 MS/s 3.3 -> 2.4 (acquisition), 5.2 -> 4.2 (tracking), 4.9 -> 4.0 (switch);
10 MS/s complex 7.4 -> 5.1, 13.1 -> 11.0, 10.1 -> 9.0; 24 MS/s real 5.0 -> 3.5, 8.7 -> 7.6, 7.8 -> 6.9. What is left
in it (thread time, a 38.192 MS/s tracking block, the last 16,384 samples at L = 64): the STFT 70 us, the noise levels
65 us (np.partition 35-45 of it: numpy's selection beats a compiled one on columns of 255-511 frames), the frame
ridges 45 us, the period search 30 us (its FFTs), the profiles, shape and residuals 40 us, the block-end frequency
30 us (numpy's linalg in the law's prediction interval, kept for its bits), and the sample-resolution hook test
(``fine_hook``): 1.5 ms on the 1 block in 20 that runs it (the analytic signal's FFTs of the block), 75-95 us a block
on average.

What the goal needs (not done): one spectrogram per block shared by the Welch features, the ridge and the
integration, and the per-block glue in compiled passes. The shared spectrogram changes the statistics (the
integration's comb and the ridge's noise-only peak excess are calibrated on their own frame lengths and overlaps), so
the thresholds and the accuracy documents (real_jammers.md, sensitivity.md, stft_shapes.md) must be measured again
with it; that did not fit in this session. The paper's "kalman" estimator is untouched.

The stages around the ridge (2026-12-07, later; bit-identical: split_reference.py --check, all 900 fields of 12
streams equal to the bit; the real-jammer table unchanged): the integration's spectral autocorrelation takes the
|X|^2, amplitudes, normalisations and FFT padding from the spectrum in one compiled pass and its noise moments in
another (per call 622 -> 523 us at 38.192 MS/s, 357 -> 245 us at 10 MS/s complex); its sums over the window and the
sub-windows are stacked (one add per statistic); the comb's fine candidates are compiled (36 -> 3 us); the complex
Welch PSD is compiled like the real one (82 -> 50 us per call at 10 MS/s); the noise template's running median is
compiled (20 -> 7 us, every block while no template is learned); interleaved I/Q become complex samples without
temporaries. In the run above, same process, alternated: integration 0.590 -> 0.448 ms (38.192 MS/s quiet), 0.888 ->
0.642 ms (10 MS/s quiet); Welch + features 0.22 -> 0.14 ms (tracking, both front ends). The ratio to the bare STFT
moved clearly only at 10 MS/s complex (27.2 -> 22.3 quiet, 19.2 -> 17.7 tracking); at 38.192 MS/s the bare STFT
itself read 0.12-0.16 ms across the children, more than these gains. What is left in these stages is FFTs and the
comb's decisions: a quiet 38.192 MS/s block added to the window costs about 4 bare STFTs (its 2,386-frame 32-point
STFT, the 15 x 4,320-point FFT of the amplitudes, the 1024-point Welch PSD), and a decision about 0.3 ms per distinct
window length (1.2 ms with the window full, every 10 ms of stamps). Cheaper only with a change of behaviour:
integrating at hop L instead of L / 2 (half the frames and FFT length; the noise model of the comb measured again),
deciding on fewer window lengths, or the constant-envelope moments over 4,096 samples instead of 8,192
(measured per call 129 -> 71 us; 1.4 bare STFTs per tracking block now; their scatter 1.4 % instead of 1 %)."""
