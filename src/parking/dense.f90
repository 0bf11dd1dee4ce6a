!> The dense strategy (`&parking strategy = 'dense'`, docs/dense.md): sieve by sieve, largest
!> first, random sequential addition as anm_parking_rsa does it (with `max_failures` replaced by
!> `dense_params_type%max_failures` when that is set); when RSA ends a sieve short of its
!> target, rounds of relaxation sweeps (hard-particle Monte Carlo moves of the parked particles)
!> and further RSA insertions follow until the target is reached, `rounds` rounds are spent or the
!> wall-clock limit passes.
!>
!> A move is a translation (probability 1/2: centre + d v, v uniform in the unit ball) or a
!> rotation (angle uniform in [-a, a] about a uniform axis) of one parked particle, accepted only
!> when `fits` finds no overlap with any other particle (the shell mode's bodies) and no wall
!> crossing: no overlap ever exists. The sizes d and a are per sieve, tuned after every sweep
!> towards the target acceptance (HOOMD-blue's scale solver: x (acc + 1) / (target + 1), within
!> x/2 .. 2x) from integer counts. With growth, a particle below its target scale spends half of its
!> trials on growth: the scale min(target, scale (1 + g)) at the same pose, g per sieve tuned like
!> the steps (within 0.5).
!>
!> Determinism: sweep k moves particles 1..np in id order (ids are stable: the strategy only adds);
!> the trial of particle i in sweep k draws from its own stream (seed xor salt, k 2^32 + i).
!> Trials are evaluated in batches in parallel against the frozen packing, then committed in id
!> order; a trial whose bounding sphere meets the old or new bounding sphere of a move committed
!> earlier in the batch is re-evaluated against the current packing. The sweep thus equals the
!> serial sweep, for any batch size and thread count. On several processes (the MPI build, with
!> replicated data) every process draws every trial of a batch, evaluates its share of them (member
!> b on process mod(b - 1, processes)) and one collective `share_outcomes` gives every process every
!> outcome; the in-order commits then run alike on every process, so the sweep is the serial one
!> for any number of processes too, and so is the wall-clock limit's decision (the longest clock
!> of the processes). Each RSA round draws its particles from the
!> sieve's streams under a seed derived from (seed, round).
!>
!> Usage:
!>     call park_dense(pk, ks, ap, rp, dp, target_fraction, result, run, error)
!>     call new_move_state(ms, max_width);  call relax_sweep(pk, ms, dp)   ! one sweep
module anm_parking_dense
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type
   use anm_core_random, only: rng_type, new_rng, splitmix64
   use anm_geometry_rotation, only: rotation_about_axis
   use anm_parking_kinds, only: kind_set_type
   use anm_parking_packing, only: packing_type, fit_scratch_type
   use anm_parking_attempts, only: attempt_params_type
   use anm_parking_rsa, only: park_rsa, rsa_params_type, sieve_result_type, run_state_type
   use anm_parking_scheduler, only: phase1_distributor_type
   use omp_lib, only: omp_get_thread_num, omp_get_max_threads
   implicit none
   private

   public :: park_dense, dense_params_type, move_state_type, new_move_state, relax_sweep

   !> Salt of the move streams (kept apart from the RSA streams (seed, sieve 2^32 + i)).
   integer(i8), parameter :: move_salt = 6148914691236517205_i8
   !> Largest rotation step (rad) and translation step (fraction of the sieve's largest width).
   real(wp), parameter :: max_angle = 1.0_wp, max_step = 0.25_wp
   !> Relative shortfall of a sieve below which no further dense round starts (0.5 %).
   real(wp), parameter :: round_tolerance = 0.005_wp
   !> Largest growth step of a growth trial (relative to the particle's scale).
   real(wp), parameter :: max_growth = 0.5_wp

   !> What the strategy needs of the run besides the RSA parameters.
   type :: dense_params_type
      !> Base seed.
      integer(i8) :: seed = 1_i8
      !> Growth: a round's insertions park at this fraction of the drawn width and grow towards it
      !> by Monte Carlo growth moves (0: no growth, insertions at full size).
      real(wp) :: grow_scale = 0.0_wp
      !> Growth: a round asks RSA for its missing volume times (1 + overfill); the growth of a sieve
      !> ends once the particles it keeps hold its target volume, the rest at the size they reached.
      real(wp) :: overfill = 0.0_wp
      !> Particles that may exhaust their attempts before one of the strategy's RSA passes ends
      !> (0: the RSA parameters' max_failures).
      integer :: max_failures = 0
      !> Shell layers given in mm (a particle short of its size would have a thinner shell).
      logical :: absolute_shells = .false.
      !> Relaxation-and-insertion rounds per sieve; sweeps per round.
      integer :: rounds = 20, sweeps = 10
      !> Acceptance ratio the move sizes are tuned to.
      real(wp) :: target_acceptance = 0.3_wp
      !> Wall-clock limit (s) after which no round starts (0: none).
      real(wp) :: time_limit = 0.0_wp
      !> Threads; trials per batch (0: 32 per thread; any value gives the same model).
      integer :: nthreads = 1, batch = 0
   end type dense_params_type

   !> Move sizes per sieve and the counters of the last sweep.
   type :: move_state_type
      !> Translation step (mm), rotation step (rad) and relative growth step of each sieve; the
      !> bound of the translation step.
      real(wp), allocatable :: d(:), a(:), g(:), dmax(:)
      !> Trials and acceptances of the last sweep per sieve: translations, rotations, growths.
      integer(i8), allocatable :: nt(:), at(:), nr(:), ar(:), ng(:), ag(:)
      !> Per particle (by id): the particle that refused its last trial, 0 for none (tested first in
      !> its next trial: no answer changes, a refusal is found sooner).
      integer, allocatable :: blk(:)
      !> Sweeps done (keys the streams).
      integer :: sweep = 0
   end type move_state_type

contains

   !> Move sizes for sieves of the given largest widths (mm): steps of 5 % of the width, 0.2 rad,
   !> growth steps of 5 % of the scale.
   pure subroutine new_move_state(ms, max_width)
      !> Move state.
      type(move_state_type), intent(out) :: ms
      !> Largest width of each sieve (mm).
      real(wp), intent(in) :: max_width(:)
      integer :: n
      n = size(max_width)
      ms%d = 0.05_wp * max_width
      ms%dmax = max_step * max_width
      allocate (ms%a(n), ms%g(n), ms%nt(n), ms%at(n), ms%nr(n), ms%ar(n), ms%ng(n), ms%ag(n))
      ms%a = 0.2_wp
      ms%g = 0.05_wp
      allocate (ms%blk(0))
      ms%nt = 0
      ms%at = 0
      ms%nr = 0
      ms%ar = 0
      ms%ng = 0
      ms%ag = 0
   end subroutine new_move_state

   !> Park every sieve (ap(s), target_fraction(s)) into pk.
   !> Length: about 90 lines; the round loop of one sieve reads best in one piece.
   subroutine park_dense(pk, ks, ap, rp, dp, target_fraction, result, run, error)
      !> Packing.
      type(packing_type), intent(inout) :: pk
      !> Kinds bookkeeping.
      type(kind_set_type), intent(inout) :: ks
      !> Attempt parameters of each sieve.
      type(attempt_params_type), intent(in) :: ap(:)
      !> RSA parameters.
      type(rsa_params_type), intent(in) :: rp
      !> Dense parameters.
      type(dense_params_type), intent(in) :: dp
      !> Target volume fraction of each sieve.
      real(wp), intent(in) :: target_fraction(:)
      !> What each sieve achieved.
      type(sieve_result_type), allocatable, intent(out) :: result(:)
      !> Run state.
      type(run_state_type), intent(inout) :: run
      !> Error (a kind that cannot be built).
      type(error_type), allocatable, intent(out) :: error
      type(move_state_type) :: ms
      type(sieve_result_type), allocatable :: r1(:)
      type(sieve_result_type) :: res, full
      type(attempt_params_type) :: a2
      type(rsa_params_type) :: rq
      real(wp), allocatable :: tsc(:)
      real(wp) :: carry, target, f, request
      integer :: s, round, j, np0
      integer(i8) :: h, hh
      logical :: grow
      allocate (result(size(ap)), tsc(0))
      ! the strategy's RSA passes: the failures they may spend
      rq = rp
      if (dp%max_failures > 0) rq%max_failures = dp%max_failures
      call new_move_state(ms, ap(:)%max_width)
      grow = dp%grow_scale > 0.0_wp
      f = merge(dp%grow_scale, 1.0_wp, grow)
      carry = 0.0_wp
      do s = 1, size(ap)
         target = max(0.0_wp, target_fraction(s) * rp%vbox + carry)
         if (pk%ndead > 0) call pk%compact()
         call park_rsa(pk, ks, ap(s:s), rq, [target / rp%vbox], r1, run, error)
         if (allocated(error)) return
         call extend_targets(tsc, pk, 1.0_wp)
         res = r1(1)
         round = 0
         do while (.not. res%reached .and. round < dp%rounds)
            if (out_of_time(dp, run, rp%dist)) exit
            round = round + 1
            ! the moves test many pairs near contact: every body gets its support table
            call ks%add_tables(pk%kinds, run%attempts, now=.true.)
            ! the sieve and the one before move: they open room for the next insertions (larger
            ! particles are settled, and moving them among many small ones is costly)
            do j = 1, dp%sweeps
               call relax_sweep(pk, ms, dp, tsc, first_sieve=max(1, s - 1), dist=rp%dist)
            end do
            a2 = ap(s)
            h = int(s, i8) * 65536_i8 + round
            call splitmix64(h, hh)
            a2%seed = ieor(ap(s)%seed, hh)
            ! with growth the round's particles park at f times their drawn width: the request is
            ! the missing volume (counted at the particles' target sizes) at that size
            a2%min_width = f * ap(s)%min_width
            a2%max_width = f * ap(s)%max_width
            full = sieve_totals(pk, s, tsc)
            request = (target - full%vol) * f**3 * (1.0_wp + dp%overfill)
            np0 = pk%np
            if (pk%ndead > 0) call pk%compact()
            call park_rsa(pk, ks, [a2], rq, [request / rp%vbox], r1, run, error)
            if (allocated(error)) return
            call extend_targets(tsc, pk, 1.0_wp / f)
            if (grow .and. pk%np > np0) then
               do j = 1, dp%sweeps
                  call relax_sweep(pk, ms, dp, tsc, first_sieve=s, near_short=.true., dist=rp%dist)
               end do
            end if
            full = sieve_totals(pk, s, tsc)
            if (grow .and. close_enough(full, target)) then
               ! enough particles once grown: grow them; those that cannot grow go (next round)
               call finish_growth(pk, ms, dp, tsc, s, ap(s)%min_width, target, rp%progress_unit, rp%vbox, run, &
                                  rp%dist)
               call settle_growth(pk, tsc, s, ap(s)%min_width, dp%absolute_shells)
               full = sieve_totals(pk, s, tsc)
            end if
            res = sieve_totals(pk, s)
            res%reached = close_enough(full, target)
            call round_line(rp, ms, s, round, res, full, target)
         end do
         if (grow) then
            call finish_growth(pk, ms, dp, tsc, s, ap(s)%min_width, target, rp%progress_unit, rp%vbox, run, rp%dist)
            call settle_growth(pk, tsc, s, ap(s)%min_width, dp%absolute_shells)
            res = sieve_totals(pk, s)
            res%reached = close_enough(res, target)
         end if
         result(s) = res
         carry = merge(target - res%vol, 0.0_wp, res%reached .and. rp%carry)
      end do
   end subroutine park_dense

   !> Whether a sieve's volume (res) is close enough to its target that no further round is
   !> worth it: short by less than half a mean particle or by less than `round_tolerance` of the
   !> target.
   pure logical function close_enough(res, target) result(yes)
      type(sieve_result_type), intent(in) :: res
      real(wp), intent(in) :: target
      yes = res%vol >= target - max(0.5_wp * res%vol / max(1, res%count), round_tolerance * target)
   end function close_enough

   !> Whether the run has passed the wall-clock limit `dp%time_limit` (never when it is 0). On
   !> several processes (`dist`; collective) the longest of their clocks decides, so that all take
   !> the same branch.
   logical function out_of_time(dp, run, dist) result(late)
      type(dense_params_type), intent(in) :: dp
      type(run_state_type), intent(in) :: run
      class(phase1_distributor_type), intent(in), optional :: dist
      integer(i8) :: t1
      real(wp) :: elapsed
      late = .false.
      if (dp%time_limit <= 0.0_wp) return
      call system_clock(t1)
      elapsed = real(t1 - run%t0, wp) / run%rate
      if (present(dist)) elapsed = dist%agree(elapsed)
      late = elapsed > dp%time_limit
   end function out_of_time

   !> Targets of the particles parked since the last call: scale times `factor` (1: at full size).
   pure subroutine extend_targets(tsc, pk, factor)
      real(wp), allocatable, intent(inout) :: tsc(:)
      type(packing_type), intent(in) :: pk
      real(wp), intent(in) :: factor
      real(wp), allocatable :: t2(:)
      integer :: n
      n = size(tsc)
      if (pk%np <= n) return
      allocate (t2(pk%np))
      t2(:n) = tsc
      t2(n + 1:) = factor * pk%scale(n + 1:pk%np)
      call move_alloc(t2, tsc)
   end subroutine extend_targets

   !> End of a sieve's growth: a particle of sieve s short of its target size stays (at its size,
   !> its target reset) when its width is still in the sieve and its shells are not in mm (a shell
   !> in mm would be thinner than prescribed); otherwise it is removed.
   subroutine settle_growth(pk, tsc, s, min_width, absolute_shells)
      type(packing_type), intent(inout) :: pk
      real(wp), allocatable, intent(inout) :: tsc(:)
      integer, intent(in) :: s
      real(wp), intent(in) :: min_width
      logical, intent(in) :: absolute_shells
      integer :: i
      logical :: removed
      removed = .false.
      do i = pk%np, 1, -1
         if (pk%sieve(i) /= s .or. pk%scale(i) >= tsc(i)) cycle
         if (keeps_short(pk, i, min_width, absolute_shells)) then
            tsc(i) = pk%scale(i)
         else
            tsc(i) = tsc(pk%np)
            call pk%remove(i)
            removed = .true.
         end if
      end do
      tsc = tsc(:pk%np)
      if (removed) call pk%compact()
   end subroutine settle_growth

   !> Whether particle i, short of its target size, may stay at its size when its sieve's growth
   !> ends: its width is still at least the sieve's `min_width` and its shells are not in mm.
   pure logical function keeps_short(pk, i, min_width, absolute_shells) result(keep)
      type(packing_type), intent(in) :: pk
      integer, intent(in) :: i
      real(wp), intent(in) :: min_width
      logical, intent(in) :: absolute_shells
      keep = .not. absolute_shells .and. pk%scale(i) * pk%kinds(pk%kind_of(i))%width >= min_width
   end function keeps_short

   !> Particles and volume of sieve s as they are in the packing, or with every particle at its
   !> target scale `tsc` (the shell fractions are summed at the end of the run: anm_parking_engine).
   pure function sieve_totals(pk, s, tsc) result(res)
      type(packing_type), intent(in) :: pk
      integer, intent(in) :: s
      real(wp), intent(in), optional :: tsc(:)
      type(sieve_result_type) :: res
      integer :: i, k
      real(wp) :: sc
      do i = 1, pk%np
         if (pk%sieve(i) /= s) cycle
         k = pk%kind_of(i)
         sc = pk%scale(i)
         if (present(tsc)) sc = tsc(i)
         res%count = res%count + 1
         res%vol = res%vol + sc**3 * pk%kinds(k)%volume
      end do
   end function sieve_totals

   !> Growth sweeps of sieve s while some of its particles are below their target size, the
   !> particles `settle_growth` would keep hold less than `target` (mm^3) and the sieve's volume still
   !> grows (stop after 10 sweeps without 0.01 % gain, after 50 x sweeps, or when the wall-clock
   !> limit has passed); only the particles still short and their neighbours move.
   !> A progress line (on `unit` >= 0) gives the sweeps done, the particles still short and the
   !> sieve's fraction.
   subroutine finish_growth(pk, ms, dp, tsc, s, min_width, target, unit, vbox, run, dist)
      type(packing_type), intent(inout) :: pk
      type(move_state_type), intent(inout) :: ms
      type(dense_params_type), intent(in) :: dp
      real(wp), intent(in) :: tsc(:)
      integer, intent(in) :: s, unit
      real(wp), intent(in) :: min_width, target, vbox
      type(run_state_type), intent(in) :: run
      class(phase1_distributor_type), intent(in), optional :: dist
      integer :: j, idle, nshort
      real(wp) :: vol, kept, best
      best = 0.0_wp
      idle = 0
      do j = 1, 50 * dp%sweeps
         call growth_state(pk, tsc, s, min_width, dp%absolute_shells, nshort, vol, kept)
         if (unit >= 0 .and. j > 1 .and. mod(j - 1, 10) == 0) then
            write (unit, '(a,i0,a,i0,a,i0,a,f8.5)') "sieve ", s, ": growth sweep ", j - 1, ", ", nshort, &
               " particles short of their size, fraction ", vol / vbox
            flush (unit)
         end if
         if (nshort == 0 .or. kept >= target) exit
         if (out_of_time(dp, run, dist)) exit
         if (vol > best * (1.0_wp + 1.0e-4_wp)) then
            best = vol
            idle = 0
         else
            idle = idle + 1
            if (idle >= 10) exit
         end if
         call relax_sweep(pk, ms, dp, tsc, first_sieve=s, near_short=.true., dist=dist)
      end do
      call growth_state(pk, tsc, s, min_width, dp%absolute_shells, nshort, vol, kept)
      if (unit >= 0 .and. j > 1) then
         write (unit, '(a,i0,a,i0,a,i0,a,f8.5)') "sieve ", s, ": growth ended after ", min(j - 1, 50 * dp%sweeps), &
            " sweeps, ", nshort, " particles short of their size, fraction ", vol / vbox
         flush (unit)
      end if
   end subroutine finish_growth

   !> Particles of sieve s below their target scale, the sieve's volume (mm^3) as it is, and the
   !> volume of the particles `settle_growth` would keep (full size, or short and `keeps_short`).
   pure subroutine growth_state(pk, tsc, s, min_width, absolute_shells, nshort, vol, kept)
      type(packing_type), intent(in) :: pk
      real(wp), intent(in) :: tsc(:)
      integer, intent(in) :: s
      real(wp), intent(in) :: min_width
      logical, intent(in) :: absolute_shells
      integer, intent(out) :: nshort
      real(wp), intent(out) :: vol, kept
      integer :: i
      real(wp) :: v
      nshort = 0
      vol = 0.0_wp
      kept = 0.0_wp
      do i = 1, pk%np
         if (pk%sieve(i) /= s) cycle
         v = pk%scale(i)**3 * pk%kinds(pk%kind_of(i))%volume
         vol = vol + v
         if (pk%scale(i) < tsc(i)) then
            nshort = nshort + 1
            if (.not. keeps_short(pk, i, min_width, absolute_shells)) cycle
         end if
         kept = kept + v
      end do
   end subroutine growth_state

   !> One relaxation sweep: one trial move per active particle (those of sieve `first_sieve` and
   !> later, default all; with `near_short` only those below their target scale and those within
   !> their reach, `growth_set`), in id order;
   !> move sizes tuned afterwards; the cell list compacted when a quarter of its records are
   !> retired. With `target` (scale per particle id), a particle below
   !> its target tries a growth step in half of its trials (`propose`).
   !> Length: about 115 lines; the batch's parallel trial, its sharing and the in-order commit belong together.
   subroutine relax_sweep(pk, ms, dp, target, first_sieve, near_short, dist)
      !> Packing.
      type(packing_type), intent(inout) :: pk
      !> Move sizes and counters.
      type(move_state_type), intent(inout) :: ms
      !> Parameters (seed, threads, batch, target acceptance).
      type(dense_params_type), intent(in) :: dp
      !> Target scale of each particle (growth).
      real(wp), intent(in), optional :: target(:)
      !> Only particles of this sieve and later sieves move (default 1: all).
      integer, intent(in), optional :: first_sieve
      !> Only particles below their target scale and their neighbours move (default false).
      logical, intent(in), optional :: near_short
      !> Processes that share the trials (the MPI build; collective): each evaluates the batch
      !> members `rank` + 1, `rank` + 1 + `nranks`, ... and `share_outcomes` gives every process
      !> every outcome; the commits then run alike everywhere. Absent: this process alone.
      class(phase1_distributor_type), intent(in), optional :: dist
      type(fit_scratch_type), allocatable :: scr(:)
      real(wp), allocatable :: xn(:, :), rn(:, :, :), sq(:), cx(:, :), cr(:), tg(:)
      logical, allocatable :: ok(:), inside(:)
      integer, allocatable :: typ(:), act(:), by(:)
      integer(i8), allocatable :: code(:)
      integer :: nb, i0, n, b, i, t, nc, s, np, s0, na, first, stride, workers
      integer(i8) :: k
      real(wp) :: rb
      real :: c0, c1
      ms%sweep = ms%sweep + 1
      k = ms%sweep
      ms%nt = 0
      ms%at = 0
      ms%nr = 0
      ms%ar = 0
      ms%ng = 0
      ms%ag = 0
      np = pk%np
      if (present(target)) then
         tg = target(:np)
      else
         tg = pk%scale(:np)
      end if
      s0 = 1
      if (present(first_sieve)) s0 = first_sieve
      if (present(near_short)) then
         if (near_short) act = growth_set(pk, tg, s0)
      end if
      if (.not. allocated(act)) act = pack([(i, i=1, np)], pk%sieve(:np) >= s0)
      ! refusers by id: entries of removed or new particles are only hints
      if (size(ms%blk) /= np) ms%blk = [ms%blk(:min(np, size(ms%blk))), (0, i=size(ms%blk) + 1, np)]
      na = size(act)
      first = 1
      stride = 1
      workers = dp%nthreads
      if (present(dist)) then
         first = dist%rank + 1
         stride = dist%nranks
         workers = dist%workers
      end if
      nb = dp%batch
      if (nb <= 0) nb = 32 * max(1, workers)
      allocate (scr(0:omp_get_max_threads() - 1), xn(3, nb), rn(3, 3, nb), sq(nb), ok(nb), inside(nb), &
                typ(nb), by(nb), code(nb))
      ! committed moves of the batch: old and new centres, bounding radius
      allocate (cx(3, 2 * nb), cr(2 * nb))
      i0 = 0
      do while (i0 < na)
         n = min(nb, na - i0)
         ! every process draws every trial (cheap); it evaluates its share of them
         if (stride > 1) call cpu_time(c0)
         !$omp parallel do default(none) shared(pk, ms, dp, xn, rn, sq, ok, inside, typ, by, n, i0, k, scr, tg, act, &
         !$omp first, stride) private(b, i, t) schedule(dynamic, 1)
         do b = 1, n
            i = act(i0 + b)
            call propose(pk, ms, dp%seed, k, i, tg(i), xn(:, b), rn(:, :, b), sq(b), typ(b), inside(b))
            if (mod(b - first, stride) /= 0) cycle
            t = omp_get_thread_num()
            call evaluate(pk, i, xn(:, b), rn(:, :, b), sq(b), inside(b), ms%blk(i), scr(t), ok(b), by(b))
         end do
         !$omp end parallel do
         if (stride > 1) then
            call cpu_time(c1)
            ! outcome code: -1 fits, else the refuser (0: none); huge where another process evaluates
            do b = 1, n
               code(b) = huge(code)
               if (mod(b - first, stride) == 0) code(b) = merge(-1_i8, int(by(b), i8), ok(b))
            end do
            call dist%share_outcomes(code(:n), real(c1 - c0, wp))
            ok(:n) = code(:n) == -1_i8
            by(:n) = int(max(0_i8, code(:n)))
         end if
         nc = 0
         do b = 1, n
            i = act(i0 + b)
            s = pk%sieve(i)
            ! the trial's reach: its largest candidate scale
            rb = pk%rho(i) * max(1.0_wp, sq(b) / pk%scale(i))
            if (inside(b)) then
               if (conflicts(pk, xn(:, b), rb, cx, cr, nc)) then
                  call evaluate(pk, i, xn(:, b), rn(:, :, b), sq(b), inside(b), ms%blk(i), scr(0), ok(b), by(b))
               end if
            end if
            select case (typ(b))
            case (1)
               ms%nt(s) = ms%nt(s) + 1
               if (ok(b)) ms%at(s) = ms%at(s) + 1
            case (2)
               ms%nr(s) = ms%nr(s) + 1
               if (ok(b)) ms%ar(s) = ms%ar(s) + 1
            case default
               ms%ng(s) = ms%ng(s) + 1
               if (ok(b)) ms%ag(s) = ms%ag(s) + 1
            end select
            if (inside(b)) ms%blk(i) = by(b)
            if (ok(b)) then
               cx(:, nc + 1) = pk%center(:, i)
               cx(:, nc + 2) = xn(:, b)
               cr(nc + 1:nc + 2) = rb
               nc = nc + 2
               call pk%move(i, xn(:, b), rn(:, :, b), sq(b))
            end if
         end do
         i0 = i0 + n
      end do
      call tune(ms, dp%target_acceptance)
      if (4 * pk%ndead > pk%np) call pk%compact()
   end subroutine relax_sweep

   !> The particles of sieve s0 and later that are below their target scale `tg`, and those of
   !> the same sieves whose bounding spheres meet such a particle's bounding sphere at its target
   !> size (they make room by moving), in id order.
   function growth_set(pk, tg, s0) result(act)
      type(packing_type), intent(in) :: pk
      real(wp), intent(in) :: tg(:)
      integer, intent(in) :: s0
      integer, allocatable :: act(:)
      logical, allocatable :: on(:)
      integer, allocatable :: ids(:)
      real(wp), allocatable :: shifts(:, :)
      integer :: i, m, n
      allocate (on(pk%np), ids(64), shifts(3, 64))
      on = .false.
      do i = 1, pk%np
         if (pk%sieve(i) < s0 .or. pk%scale(i) >= tg(i)) cycle
         on(i) = .true.
         call pk%neighbours(pk%center(:, i), pk%rho(i) * tg(i) / pk%scale(i), ids, shifts, n)
         do m = 1, n
            if (pk%sieve(ids(m)) >= s0) on(ids(m)) = .true.
         end do
      end do
      act = pack([(i, i=1, pk%np)], on)
   end function growth_set

   !> Outcome of the trial of particle i (pose x, r; scale sq; inside): ok when it fits (one
   !> certified `fits` test; a growth trial's sq is its grown scale). The result depends only on
   !> the particle and the packing within the trial's reach; `hint` (tested first) and `by` (the
   !> particle that refused the trial, 0 for none) only change how soon a refusal is found.
   subroutine evaluate(pk, i, x, r, sq, inside, hint, scr, ok, by)
      type(packing_type), intent(in) :: pk
      integer, intent(in) :: i, hint
      real(wp), intent(in) :: x(3), r(3, 3), sq
      logical, intent(in) :: inside
      type(fit_scratch_type), intent(inout) :: scr
      logical, intent(out) :: ok
      integer, intent(out) :: by
      ok = .false.
      by = 0
      if (.not. inside) return
      ok = pk%fits(pk%kind_of(i), x, r, sq, scr, exclude=i, hint=hint, blocker=by)
   end subroutine evaluate

   !> The trial of particle i in sweep k: new centre x, rotation r and scale sc; typ 1
   !> translation, 2 rotation, 3 growth (a particle below its target scale `tgt`, half of its
   !> trials: sc = min(tgt, scale (1 + g)), g the sieve's growth step); inside false when a walled
   !> box's centre would leave the box.
   subroutine propose(pk, ms, seed, k, i, tgt, x, r, sc, typ, inside)
      type(packing_type), intent(in) :: pk
      type(move_state_type), intent(in) :: ms
      integer(i8), intent(in) :: seed, k
      integer, intent(in) :: i
      real(wp), intent(in) :: tgt
      real(wp), intent(out) :: x(3), r(3, 3), sc
      integer, intent(out) :: typ
      logical, intent(out) :: inside
      type(rng_type) :: rng
      real(wp) :: v(3), axis(3)
      integer :: s, d
      s = pk%sieve(i)
      call new_rng(rng, ieor(seed, move_salt), k * 4294967296_i8 + i)
      x = pk%center(:, i)
      r = pk%rot(:, :, i)
      sc = pk%scale(i)
      inside = .true.
      if (sc < tgt) then
         if (rng%uniform() < 0.5_wp) then
            typ = 3
            sc = min(tgt, sc * (1.0_wp + ms%g(s)))
            return
         end if
      end if
      if (rng%uniform() < 0.5_wp) then
         typ = 1
         do
            do d = 1, 3
               v(d) = 2.0_wp * rng%uniform() - 1.0_wp
            end do
            if (sum(v**2) <= 1.0_wp) exit
         end do
         x = x + ms%d(s) * v
         if (pk%p%periodic) then
            x = modulo(x, pk%p%box)
            ! modulo of a tiny negative value may round to the box edge
            where (x >= pk%p%box) x = 0.0_wp
         else
            inside = all(x > 0.0_wp .and. x < pk%p%box)
         end if
      else
         typ = 2
         do
            do d = 1, 3
               axis(d) = rng%normal()
            end do
            if (sum(axis**2) > 1.0e-12_wp) exit
         end do
         r = matmul(rotation_about_axis(axis, ms%a(s) * (2.0_wp * rng%uniform() - 1.0_wp)), r)
      end if
   end subroutine propose

   !> Whether the bounding sphere (x, rho) meets one of the nc committed spheres (nearest image;
   !> conservatively true when the spheres span half the box).
   pure logical function conflicts(pk, x, rho, cx, cr, nc) result(hit)
      type(packing_type), intent(in) :: pk
      real(wp), intent(in) :: x(3), rho, cx(:, :), cr(:)
      integer, intent(in) :: nc
      real(wp) :: e(3)
      integer :: m
      hit = .true.
      do m = 1, nc
         if (pk%p%periodic .and. 2.0_wp * (rho + cr(m)) >= minval(pk%p%box)) return
         e = x - cx(:, m)
         if (pk%p%periodic) e = e - pk%p%box * anint(e / pk%p%box)
         if (sum(e**2) < (rho + cr(m))**2) return
      end do
      hit = .false.
   end function conflicts

   !> Tune the move sizes (translation, rotation, growth) of every sieve moved in the last sweep
   !> towards the target acceptance.
   pure subroutine tune(ms, target)
      type(move_state_type), intent(inout) :: ms
      real(wp), intent(in) :: target
      integer :: s
      real(wp) :: acc
      do s = 1, size(ms%d)
         if (ms%nt(s) > 0) then
            acc = real(ms%at(s), wp) / real(ms%nt(s), wp)
            ms%d(s) = min(ms%dmax(s), max(0.5_wp * ms%d(s), min(2.0_wp * ms%d(s), ms%d(s) * (acc + 1.0_wp) &
                                                                 / (target + 1.0_wp))))
         end if
         if (ms%ng(s) > 0) then
            acc = real(ms%ag(s), wp) / real(ms%ng(s), wp)
            ms%g(s) = min(max_growth, max(0.5_wp * ms%g(s), min(2.0_wp * ms%g(s), ms%g(s) * (acc + 1.0_wp) &
                                                                 / (target + 1.0_wp))))
         end if
         if (ms%nr(s) > 0) then
            acc = real(ms%ar(s), wp) / real(ms%nr(s), wp)
            ms%a(s) = min(max_angle, max(0.5_wp * ms%a(s), min(2.0_wp * ms%a(s), ms%a(s) * (acc + 1.0_wp) &
                                                               / (target + 1.0_wp))))
         end if
      end do
   end subroutine tune

   !> The line closing a round.
   subroutine round_line(rp, ms, s, round, res, full, target)
      type(rsa_params_type), intent(in) :: rp
      type(move_state_type), intent(in) :: ms
      integer, intent(in) :: s, round
      type(sieve_result_type), intent(in) :: res, full
      real(wp), intent(in) :: target
      real(wp) :: acc
      if (rp%progress_unit < 0) return
      acc = real(ms%at(s) + ms%ar(s) + ms%ag(s), wp) / max(1.0_wp, real(ms%nt(s) + ms%nr(s) + ms%ng(s), wp))
      write (rp%progress_unit, '(a,i0,a,i0,a,i0,a,f8.5,a,f8.5,a,f8.5,a,f5.3,a,es9.2,a,f6.3,a)') "sieve ", s, &
         ": dense round ", round, ", ", res%count, " particles, fraction ", res%vol / rp%vbox, " (", &
         full%vol / rp%vbox, " when grown) of ", target / rp%vbox, ", acceptance ", acc, ", step ", ms%d(s), &
         " mm, ", ms%a(s), " rad"
      flush (rp%progress_unit)
   end subroutine round_line
end module anm_parking_dense
