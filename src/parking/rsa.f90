!> The random sequential addition strategy (thesis section 2.1, Fig 1.3): sieve by sieve, largest
!> first, particles are parked one at a time at random poses without overlap until the sieve's
!> target volume is reached or its attempts are exhausted.
!>
!> A sieve that reaches its volume ends within half a particle of it (the last particle is kept
!> only if it brings the volume closer to the target); that rounding difference (either sign)
!> moves to the next sieve so that the cumulative gradation and the total stay on target. A
!> shortfall from exhausted attempts is not carried. The thesis' rules are options
!> (`overshoot`: the last particle is always kept, so a sieve ends at or above its target;
!> `carry = .false.`: every sieve aims at its own prescribed volume; docs/thesis-gaps.md). A particle that exhausts its attempts
!> counts as a failure; the sieve ends after `max_failures` of them (the thesis: the first).
!>
!> Particles are speculated in batches (anm_parking_scheduler): the model does not depend on the
!> batch size nor on the number of threads.
!>
!> Usage:
!>     call park_rsa(pk, ks, ap, rp, target_fraction, result, run, error)
module anm_parking_rsa
   use anm_core_kinds, only: wp, i8, pi
   use anm_core_error, only: error_type
   use anm_core_strings, only: to_string
   use anm_parking_kinds, only: kind_set_type, body_holder
   use anm_parking_packing, only: packing_type, fit_scratch_type
   use anm_parking_attempts, only: attempt_params_type, first_kind_of
   use anm_parking_scheduler, only: batch_type, next_batch, phase1_distributor_type
   use anm_parking_void_grid, only: void_grid_type, new_void_grid
   implicit none
   private

   public :: park_rsa, rsa_params_type, sieve_result_type, run_state_type

   !> Void placement: the void grid advances (blocks the particles parked since its last advance,
   !> compacts when a quarter of its free list is stale) only after every `void_epoch` particles
   !> (streams) of a sieve. Every attempt of an epoch thus draws its centre from the same grid,
   !> whatever the batch sizes and the number of threads. A batch may cross epoch boundaries when
   !> the last advance left the grid unchanged (fine grains among coarse particles block no cell):
   !> its phase 1 drew from the grid as it stands, so it stays exact while each boundary crossed
   !> leaves the grid unchanged; at the first boundary that changes it, phase 2 stops and the rest
   !> of the batch is speculated again (the next batch restarts their streams). Otherwise batches
   !> end at the boundaries.
   integer, parameter :: void_epoch = 64

   !> What the strategy needs of the run besides the per-sieve attempt parameters.
   type :: rsa_params_type
      !> Particles that may exhaust their attempts before a sieve ends.
      integer :: max_failures = 1
      !> The particle that takes a sieve past its target is always kept (the thesis), else only if
      !> it brings the volume closer to the target.
      logical :: overshoot = .false.
      !> A sieve that reached its target passes its rounding difference to the next one.
      logical :: carry = .true.
      !> Kinds built per particle when first needed (one shape and one size per particle), else
      !> per sieve.
      logical :: lazy = .false.
      !> Void placement.
      logical :: void = .false.
      !> Largest batch; threads.
      integer :: batch_limit = huge(1), nthreads = 1
      !> Box volume (mm^3).
      real(wp) :: vbox = 1.0_wp
      !> Shell layers.
      integer :: nlayer = 0
      !> Unit for progress lines (< 0: none).
      integer :: progress_unit = -1
      !> Phase 1 spread over processes (the MPI build; unallocated: this process alone).
      class(phase1_distributor_type), allocatable :: dist
   end type rsa_params_type

   !> What a sieve achieved.
   type :: sieve_result_type
      !> Particles parked, their volume (mm^3) and the shell volume fraction they add.
      integer :: count = 0
      real(wp) :: vol = 0.0_wp, shell_fraction = 0.0_wp
      !> The sieve reached its target (rather than exhausting attempts).
      logical :: reached = .false.
   end type sieve_result_type

   !> State carried across sieves: batch size, clock, attempts.
   type :: run_state_type
      integer :: batch = 1
      integer(i8) :: t0 = 0, tlast = 0, rate = 1
      !> Attempts of the run so far.
      integer(i8) :: attempts = 0
      !> Target volume of the whole run (mm^3, set by the driver) and the volume parked by the
      !> sieves already finished (for the progress line's percent and time left).
      real(wp) :: vol_total = 0.0_wp, vol_done = 0.0_wp
   end type run_state_type

   !> State of the sieve being parked.
   type :: sieve_state_type
      integer :: sieve = 0, nstream = 0, failures = 0, predicted = 0
      real(wp) :: target = 0.0_wp, target_fraction = 0.0_wp
      integer(i8) :: attempts = 0
      logical :: done = .false.
      !> Void placement: particles blocked in the grid so far; the last advance changed no cell.
      integer :: np_blocked = 0
      logical :: grid_quiet = .false.
      type(sieve_result_type) :: res
   end type sieve_state_type

contains

   !> Park every sieve (ap(s), target_fraction(s)) into pk.
   subroutine park_rsa(pk, ks, ap, rp, target_fraction, result, run, error)
      !> Packing.
      type(packing_type), intent(inout) :: pk
      !> Kinds bookkeeping (kinds are built as needed into pk%kinds).
      type(kind_set_type), intent(inout) :: ks
      !> Attempt parameters of each sieve.
      type(attempt_params_type), intent(in) :: ap(:)
      !> Strategy parameters.
      type(rsa_params_type), intent(in) :: rp
      !> Target volume fraction of each sieve.
      real(wp), intent(in) :: target_fraction(:)
      !> What each sieve achieved.
      type(sieve_result_type), allocatable, intent(out) :: result(:)
      !> Run state (batch size, clock, attempts).
      type(run_state_type), intent(inout) :: run
      !> Error (a kind that cannot be built).
      type(error_type), allocatable, intent(out) :: error
      type(sieve_state_type) :: st
      real(wp) :: carry
      integer :: s
      allocate (result(size(ap)))
      carry = 0.0_wp
      do s = 1, size(ap)
         st = sieve_state_type(sieve=ap(s)%sieve, target_fraction=target_fraction(s))
         st%target = max(0.0_wp, target_fraction(s) * rp%vbox + carry)
         call park_sieve(pk, ks, ap(s), rp, st, run, error)
         if (allocated(error)) return
         result(s) = st%res
         run%vol_done = run%vol_done + st%res%vol
         carry = merge(st%target - st%res%vol, 0.0_wp, st%res%reached .and. rp%carry)
      end do
   end subroutine park_rsa

   !> Park one sieve.
   subroutine park_sieve(pk, ks, ap, rp, st, run, error)
      type(packing_type), intent(inout) :: pk
      type(kind_set_type), intent(inout) :: ks
      type(attempt_params_type), intent(in) :: ap
      type(rsa_params_type), intent(in) :: rp
      type(sieve_state_type), intent(inout) :: st
      type(run_state_type), intent(inout) :: run
      type(error_type), allocatable, intent(out) :: error
      type(void_grid_type) :: vg
      type(batch_type) :: bt
      integer :: k, batch_now, nstream0
      logical :: changed
      integer(i8) :: tp1, t1
      real(wp) :: r_in, seconds, reach
      r_in = 0.0_wp
      if (rp%void .or. .not. rp%lazy) then
         call ks%build(pk%kinds, [(k, k=ap%first_kind, ap%first_kind + ap%nkind - 1)], error)
         if (allocated(error)) return
      end if
      if (rp%void) call start_void(vg, pk, ap, r_in)
      st%np_blocked = pk%np
      ! slabs (spatial decomposition): the reach of this sieve's candidates; set every batch, as
      ! lazy kinds may be built with a larger radius
      if (pk%p%nslab > 1) pk%reach = 0.0_wp
      do while (st%res%vol < st%target .and. .not. st%done)
         if (rp%lazy) then
            call build_ahead(pk, ks, ap, rp, st, run%batch, error)
            if (allocated(error)) return
         end if
         if (pk%p%nslab > 1) then
            reach = sieve_reach(pk, ap)
            ! divided arrays: a reach beyond what the arrays hold needs the other processes'
            ! particles (every process computes the same reach and held_reach: collective alike)
            if (pk%p%divided .and. reach > pk%held_reach) call rp%dist%complete_region(pk, reach)
            call pk%set_reach(reach)
         end if
         batch_now = run%batch
         ! void placement: a batch crosses an epoch boundary only while the grid is quiet (see
         ! void_epoch)
         if (rp%void .and. .not. st%grid_quiet) batch_now = min(batch_now, void_epoch - mod(st%nstream, void_epoch))
         nstream0 = st%nstream
         call system_clock(tp1)
         call bt%speculate(batch_now, ap, pk, vg, st%nstream, rp%dist, window(st))
         call system_clock(t1)
         seconds = real(t1 - tp1, wp) / run%rate
         ! every process sizes the next batch alike
         if (allocated(rp%dist)) seconds = rp%dist%agree(seconds)
         call settle_batch(bt, pk, ap, rp, vg, st, run)
         ! support tables once the attempts pay for them (no effect on the model)
         call ks%add_tables(pk%kinds, run%attempts)
         ! slabs: the batch's particles out of this process' reach leave its cell list
         call pk%localize(bt%np_frozen + 1)
         ! slabs: moved now and then so that the processes' work evens out (no effect on the model)
         if (allocated(rp%dist) .and. pk%p%nslab > 1) call rp%dist%balance(pk)
         call reserve_ahead(pk, st)
         if (rp%void .and. mod(st%nstream, void_epoch) == 0 .and. pk%np > st%np_blocked) then
            call advance_void(vg, pk, st, changed)
         else if (rp%void .and. mod(st%nstream, void_epoch) == 0) then
            ! a batch stopped at a boundary it has already advanced (settle_batch), or an epoch
            ! that parked nothing: the same grid
            if (vg%nfree == 0) st%done = .true.
         end if
         ! a batch cut short by a changed grid is sized by the part that was settled
         if (st%nstream - nstream0 < batch_now) then
            seconds = seconds * max(1, st%nstream - nstream0) / batch_now
            batch_now = max(1, st%nstream - nstream0)
         end if
         run%batch = min(rp%batch_limit, next_batch(batch_now, seconds, st%target - st%res%vol, &
                                                    st%res%vol, st%res%count, rp%nthreads))
         call progress_line(rp, st, run)
      end do
      st%res%reached = st%res%reached .or. st%res%vol >= st%target
      if (allocated(rp%dist) .and. pk%p%nslab > 1) call rp%dist%note_slab(ap%sieve, count(pk%record(:pk%np) > 0), &
                                                                            pk%ntotal, merge(pk%np, 0, pk%p%divided))
      call sieve_report(rp, st, run, vg, r_in)
   end subroutine park_sieve

   !> Void placement: block the particles parked since the last advance, compact the free list
   !> when a quarter of it is stale; `changed` when a cell was blocked (the draws change).
   subroutine advance_void(vg, pk, st, changed)
      type(void_grid_type), intent(inout) :: vg
      type(packing_type), intent(in) :: pk
      type(sieve_state_type), intent(inout) :: st
      logical, intent(out) :: changed
      integer :: j, stale0
      stale0 = vg%stale
      do j = st%np_blocked + 1, pk%np
         call block_particle(vg, pk, j)
      end do
      st%np_blocked = pk%np
      changed = vg%stale /= stale0
      if (vg%stale > vg%nfree / 4) call vg%compact()
      if (vg%nfree == 0) st%done = .true.
      st%grid_quiet = .not. changed
   end subroutine advance_void

   !> Phase 2 of a batch: settle its particles in order and park them until the sieve ends. With
   !> void placement, the grid advances at each epoch boundary inside the batch; when that changes
   !> it, the rest of the batch (speculated on the old grid) is left for the next batch.
   subroutine settle_batch(bt, pk, ap, rp, vg, st, run)
      type(batch_type), intent(inout) :: bt
      type(packing_type), intent(inout) :: pk
      type(attempt_params_type), intent(in) :: ap
      type(rsa_params_type), intent(in) :: rp
      type(void_grid_type), intent(inout) :: vg
      type(sieve_state_type), intent(inout) :: st
      type(run_state_type), intent(inout) :: run
      type(fit_scratch_type) :: scratch
      integer :: b, k
      real(wp) :: sc, vol, vol_with
      logical :: keep, changed
      do b = 1, bt%n
         if (rp%void .and. b > 1 .and. mod(st%nstream, void_epoch) == 0) then
            call advance_void(vg, pk, st, changed)
            if (changed .or. st%done) exit
         end if
         st%nstream = st%nstream + 1
         call bt%settle(b, ap, pk, vg, scratch, rp%dist, window(st))
         associate (a => bt%at(b))
            run%attempts = run%attempts + a%count - merge(1, 0, a%done)
            st%attempts = st%attempts + a%count - merge(1, 0, a%done)
            if (a%done) then
               ! this particle exhausted its attempts: the sieve ends after max_failures such
               ! particles (the thesis: the first); later particles of the batch go on
               st%failures = st%failures + 1
               if (st%failures >= rp%max_failures) then
                  st%done = .true.
                  exit
               end if
               cycle
            end if
            k = a%k
            sc = a%sc
            ! the sieve's volume with this particle: one expression (the compiler contracts it to a
            ! fused multiply-add, as the models were recorded)
            vol = st%res%vol
            vol_with = vol + sc**3 * pk%kinds(k)%volume
            keep = rp%overshoot .or. vol_with <= st%target .or. (vol_with - st%target) <= (st%target - vol)
            if (.not. keep) then
               st%done = .true.
               st%res%reached = .true.
               exit
            end if
            call pk%add(k, a%c, a%r, sc, ap%sieve)
            call bt%accept(b)
            st%res%vol = vol_with
            st%res%count = st%res%count + 1
            if (st%res%vol >= st%target) exit
         end associate
      end do
   end subroutine settle_batch

   !> First window of a spatial search (anm_parking_scheduler): the sieve's attempts per particle
   !> so far (any value gives the same attempts; this one wastes few draws and reductions).
   pure integer function window(st)
      type(sieve_state_type), intent(in) :: st
      window = int(min(1024_i8, max(1_i8, st%attempts / max(1, st%res%count + st%failures))))
   end function window

   !> The largest bounding radius (mm) of a candidate of the sieve, over its kinds built so far.
   pure real(wp) function sieve_reach(pk, ap) result(r)
      type(packing_type), intent(in) :: pk
      type(attempt_params_type), intent(in) :: ap
      integer :: k
      r = 0.0_wp
      do k = ap%first_kind, ap%first_kind + ap%nkind - 1
         if (pk%kinds(k)%width > 0.0_wp) r = max(r, ap%max_width / pk%kinds(k)%width * pk%kinds(k)%r_out)
      end do
   end function sieve_reach

   !> Room in the packing for the particles the sieve will probably still park (the missing volume
   !> over the mean particle volume so far, plus 2 %), once the mean is known (1,000 particles):
   !> 10^7 particles then grow the arrays once to about their final size instead of doubling them
   !> (which leaves up to half unused and holds old and new arrays together while copying).
   subroutine reserve_ahead(pk, st)
      type(packing_type), intent(inout) :: pk
      type(sieve_state_type), intent(in) :: st
      integer, parameter :: min_count = 1000
      real(wp) :: more
      if (st%res%count < min_count) return
      more = 1.02_wp * max(0.0_wp, st%target - st%res%vol) / (st%res%vol / st%res%count)
      ! divided arrays: this process holds about its share of what comes
      if (pk%p%divided) more = more * pk%np / max(1, pk%ntotal)
      call pk%reserve(int(min(real(pk%np, wp) + more + min_count, 0.5_wp * huge(1))))
   end subroutine reserve_ahead

   !> Lazy kinds: build the kinds of the next batch and of the particles the sieve will probably
   !> still need (the missing volume over the mean particle volume: a sphere of the mean width
   !> until particles are parked), together so that they build in parallel. (Twice that volume
   !> built twice the kinds needed: with shells in mm 202 kinds of 4.5 MB for 101 particles.)
   subroutine build_ahead(pk, ks, ap, rp, st, batch, error)
      type(packing_type), intent(inout) :: pk
      type(kind_set_type), intent(inout) :: ks
      type(attempt_params_type), intent(in) :: ap
      type(rsa_params_type), intent(in) :: rp
      type(sieve_state_type), intent(inout) :: st
      integer, intent(in) :: batch
      type(error_type), allocatable, intent(out) :: error
      real(wp) :: vmean
      integer :: horizon, j
      if (st%res%count > 0) then
         vmean = st%res%vol / st%res%count
      else
         vmean = pi / 6.0_wp * (0.5_wp * (ap%min_width + ap%max_width))**3
      end if
      horizon = st%nstream + max(batch, rp%nthreads + int(min(4096.0_wp, max(0.0_wp, st%target - st%res%vol) &
                                                                / vmean)))
      if (horizon <= st%predicted) return
      call ks%build(pk%kinds, [(first_kind_of(ap, j), j=st%predicted + 1, horizon)], error)
      if (allocated(error)) return
      st%predicted = horizon
   end subroutine build_ahead

   !> A void grid for the sieve (cells for its smallest inscribed radius r_in) with every parked
   !> particle blocked.
   subroutine start_void(vg, pk, ap, r_in)
      type(void_grid_type), intent(out) :: vg
      type(packing_type), intent(in) :: pk
      type(attempt_params_type), intent(in) :: ap
      real(wp), intent(out) :: r_in
      integer :: k, j
      ! inscribed radius of the smallest particle this sieve can make
      r_in = huge(1.0_wp)
      do k = ap%first_kind, ap%first_kind + ap%nkind - 1
         r_in = min(r_in, pk%kinds(body_holder(pk%kinds, k))%body%r_min * ap%min_width / pk%kinds(k)%width)
      end do
      call new_void_grid(vg, pk%p%box, pk%p%periodic, r_in, 2**24)
      do j = 1, pk%np
         call block_particle(vg, pk, j)
      end do
      call vg%compact()
   end subroutine start_void

   !> Block the void-grid cells made invalid by parked particle j.
   subroutine block_particle(vg, pk, j)
      type(void_grid_type), intent(inout) :: vg
      type(packing_type), intent(in) :: pk
      integer, intent(in) :: j
      associate (bj => pk%kinds(body_holder(pk%kinds, pk%kind_of(j)))%body)
         call vg%block_particle(bj%shape, pk%center(:, j), pk%rot(:, :, j), pk%scale(j), pk%scale(j) * bj%r_min, &
                                pk%rho(j), body=bj)
      end associate
   end subroutine block_particle

   !> A progress line about every two seconds.
   subroutine progress_line(rp, st, run)
      type(rsa_params_type), intent(in) :: rp
      type(sieve_state_type), intent(in) :: st
      type(run_state_type), intent(inout) :: run
      integer(i8) :: t1
      real(wp) :: elapsed, done
      character(len=:), allocatable :: left
      if (rp%progress_unit < 0) return
      call system_clock(t1)
      if (real(t1 - run%tlast, wp) / run%rate <= 2.0_wp) return
      elapsed = real(t1 - run%t0, wp) / run%rate
      done = 0.0_wp
      if (run%vol_total > 0.0_wp) done = min(1.0_wp, (run%vol_done + st%res%vol) / run%vol_total)
      ! time left from the volume rate so far: finer sieves fill more slowly, so this is a lower
      ! estimate early in the run
      left = "time left unknown"
      if (done > 0.0_wp) left = "about "//to_string(nint(elapsed * (1.0_wp - done) / done))//" s left"
      write (rp%progress_unit, '(a,i0,a,i0,a,f8.5,a,f8.5,a,f5.1,a,es10.3,a)') "sieve ", st%sieve, ": placed ", &
         st%res%count, ", fraction ", st%res%vol / rp%vbox, " of ", st%target_fraction, "; run ", 100.0_wp * done, &
         " % of the target volume, "//left//", ", real(run%attempts, wp) / max(1.0e-9_wp, elapsed), " attempts/s"
      flush (rp%progress_unit)   ! a log file shows the line now, not at exit (stderr may be block-buffered)
      run%tlast = t1
   end subroutine progress_line

   !> The lines that close a sieve.
   subroutine sieve_report(rp, st, run, vg, r_in)
      type(rsa_params_type), intent(in) :: rp
      type(sieve_state_type), intent(in) :: st
      type(run_state_type), intent(in) :: run
      type(void_grid_type), intent(in) :: vg
      real(wp), intent(in) :: r_in
      integer(i8) :: t1
      integer :: u
      real(wp) :: f
      if (rp%progress_unit < 0) return
      u = rp%progress_unit
      f = st%res%vol / rp%vbox
      call system_clock(t1)
      write (u, '(a,i0,a,i0,a,f8.5,a,f8.5,a,i0,a,i0,a,f7.1,a)') "sieve ", st%sieve, " done: ", st%res%count, &
         " particles, fraction ", f, " (target ", st%target_fraction, "), ", st%attempts, " attempts, ", &
         st%failures, " particles not parked, ", real(t1 - run%t0, wp) / run%rate, " s"
      if (rp%void) write (u, '(a,i0,a,f8.5,a,es10.3,a)') "sieve ", st%sieve, ": void grid free fraction ", &
         vg%free_fraction(), " (inscribed radius ", r_in, " mm)"
      if (.not. st%res%reached .and. st%target_fraction - f > 0.01_wp * st%target_fraction) then
         write (u, '(a,i0,a,f8.5,a)') "warning: sieve ", st%sieve, " ended ", st%target_fraction - f, &
            " short of its target (attempts exhausted)"
      end if
      flush (u)
   end subroutine sieve_report
end module anm_parking_rsa
