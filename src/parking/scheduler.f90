!> The batch scheduler of the parking: speculate a batch of particles in parallel, then settle them
!> in stream order, so that any batch size and any number of threads give the serial model.
!>
!> Phase 1 (`speculate`, parallel): the batch's particles each find their first fitting attempt
!> against the packing as it is (frozen). Phase 2 (`settle`, in order, by the strategy): each is
!> re-checked against the particles parked since the batch started and, if hit, continues its own
!> attempt sequence. Adding particles only adds overlaps, so this is exactly the serial result.
!> The re-check is skipped for a particle whose bounding sphere meets no earlier one of the batch
!> (`first_in_reach`, parallel) nor any earlier one parked elsewhere than its phase-1 position
!> (`moved`, recorded by `accept`).
!>
!> Usage:
!>     call bt%speculate(n, ap, pk, vg, nstream)
!>     do b = 1, n
!>        call bt%settle(b, ap, pk, vg, scratch)
!>        ... decide; if parked: call pk%add(...); call bt%accept(b)
!>     end do
!>     n = next_batch(n, seconds, missing, vol, count, nthreads)
!>
!> Phase 1 may also run on several processes: a `phase1_distributor_type` (the MPI build's
!> anm_mpi_distributor, mpi/src/) leaves every member's attempt on every process as one process
!> would, in one of two ways:
!> - replicated: every process holds the whole packing and runs some members (`run_phase1` with a
!>   first member and a stride); the attempts are then gathered;
!> - spatial (`spatial_search`): process r owns slab r of equal slabs along x and holds only the
!>   particles a candidate centred in its slab can meet (`packing_type%localize`). Every process
!>   draws every attempt of every member (draws are cheap) in windows of attempts, tests only the
!>   attempts centred in its slab, and stops at its first fit; the member's first fitting attempt
!>   is the smallest over the processes (`agree_first`): every earlier attempt was tested by its
!>   owner and did not fit. Every process then replays the member's stream to that attempt. The
!>   continuation of a member hit in phase 2 is searched the same way (`settle` with `dist`).
module anm_parking_scheduler
   use anm_core_kinds, only: wp, i8
   use anm_parking_attempts, only: attempt_type, attempt_params_type
   use anm_parking_packing, only: packing_type, fit_scratch_type
   use anm_parking_void_grid, only: void_grid_type
   use anm_parking_kinds, only: kind_exchange_type
   implicit none
   private

   public :: batch_type, next_batch, first_in_reach, run_phase1, phase1_distributor_type, spatial_search

   !> One batch of speculated particles.
   type :: batch_type
      !> Number of particles.
      integer :: n = 0
      !> Attempt sequences (their current attempt is the particle's pose).
      type(attempt_type), allocatable :: at(:)
      !> Packing mark and number of particles when phase 1 ran.
      integer :: frozen = 0, np_frozen = 0
      !> Bounding radii of the phase-1 poses; no earlier phase-1 pose within reach.
      real(wp), allocatable :: br(:)
      logical, allocatable :: alone(:)
      !> Particle b left its phase-1 pose in phase 2.
      logical, allocatable :: moved_flag(:)
      !> Particles parked at another pose than their phase-1 one, in order.
      integer, allocatable :: moved(:)
      integer :: nmoved = 0
   contains
      !> Phase 1.
      procedure :: speculate
      !> Phase 2 for one particle.
      procedure :: settle
      !> Record that particle b was parked.
      procedure :: accept
   end type batch_type

   !> Phase 1 spread over processes that each hold the whole packing (replicated data). After
   !> `phase1`, every process holds every member's attempt exactly as `run_phase1` over all members
   !> leaves it; phase 2 then runs identically everywhere. Extended by the MPI build; the serial
   !> program uses none.
   type, abstract :: phase1_distributor_type
      !> Threads over all processes (sizes the batches, the same on every process).
      integer :: workers = 1
      !> This process writes the outputs and progress lines.
      logical :: writer = .true.
      !> Spatial decomposition: this process owns slab `slab` (0-based) of `nslab` along x, its
      !> packing is local (`packing_params_type%nslab`), and the attempts are searched with
      !> `spatial_search`; else replicated data.
      logical :: spatial = .false.
      integer :: nslab = 1, slab = 0
      !> This process' rank (0-based) and the number of processes: with replicated data a batch's
      !> members b = rank + 1, rank + 1 + nranks, ... run on this process.
      integer :: rank = 0, nranks = 1
      !> Processes on this process' machine (they share its memory).
      integer :: ranks_on_node = 1
   contains
      !> Phase 1 of the batch `at` on every process (collective).
      procedure(distributed_phase1), deferred :: phase1
      !> The largest value over the processes (collective): values that steer the run, such as
      !> the batch clock, must agree.
      procedure(agreed_value), deferred :: agree
      !> The smallest of each value over the processes, in place (collective; spatial mode).
      procedure(agreed_first), deferred :: agree_first
      !> At the end of a sieve: the particles in this process' cell list, in the packing and in
      !> this process' arrays (spatial mode; this default records nothing).
      procedure :: note_slab
      !> The processes' sharing of the kinds' building (this default: none, each builds all).
      procedure :: kinds_exchange
      !> Between batches (collective in spatial mode): move the slabs so that the processes'
      !> work evens out (this default: never). The slabs never change the model.
      procedure :: balance
      !> The outcomes of a batch of trials that the processes evaluated in shares (collective):
      !> each process holds huge() where it did not evaluate a member; on return entry b holds the
      !> smallest value over the processes, the evaluating one's (this default, one process:
      !> unchanged).
      procedure :: share_outcomes
      !> Divided particle arrays (collective): make this process' arrays complete for a larger
      !> reach, from the particles the others own (this default, one process: nothing to do).
      procedure :: complete_region
      !> Divided particle arrays, after the parking (collective): the particles in blocks of
      !> consecutive global ids, block r on process r (this default: unchanged).
      procedure :: to_blocks
      !> Whether each entry is true on some process, in place (collective; this default: as is).
      procedure :: any_over_ranks
      !> Sums over particles in their global order when each process holds a block of them
      !> (collective, in two steps around this process' own terms): `running_start` gives the
      !> sums over the blocks before this one, `running_end` passes them on and returns the
      !> totals on every process (these defaults, one process: unchanged).
      procedure :: running_start
      !> The second step of those sums (see `running_start`).
      procedure :: running_end
   end type phase1_distributor_type

   abstract interface
      subroutine distributed_phase1(self, at, ap, pk, vg, nstream, window)
         import :: phase1_distributor_type, attempt_type, attempt_params_type, packing_type, void_grid_type
         !> Distributor.
         class(phase1_distributor_type), intent(in) :: self
         !> Attempts of the batch.
         type(attempt_type), intent(inout) :: at(:)
         !> Parameters of the sieve.
         type(attempt_params_type), intent(in) :: ap
         !> Packing (frozen, the same on every process).
         type(packing_type), intent(in) :: pk
         !> Void grid.
         type(void_grid_type), intent(in) :: vg
         !> Particles of the sieve before this batch.
         integer, intent(in) :: nstream
         !> Attempts of the first window (spatial mode).
         integer, intent(in) :: window
      end subroutine distributed_phase1

      subroutine agreed_first(self, k)
         import :: phase1_distributor_type, i8
         !> Distributor.
         class(phase1_distributor_type), intent(in) :: self
         !> This process' values; on return the smallest over the processes.
         integer(i8), intent(inout) :: k(:)
      end subroutine agreed_first

      function agreed_value(self, x) result(y)
         import :: phase1_distributor_type, wp
         !> Distributor.
         class(phase1_distributor_type), intent(in) :: self
         !> This process' value.
         real(wp), intent(in) :: x
         real(wp) :: y
      end function agreed_value
   end interface

contains

   !> Default of `balance`: the slabs stay.
   subroutine balance(self, pk)
      !> Distributor.
      class(phase1_distributor_type), intent(in) :: self
      !> This process' packing.
      type(packing_type), intent(inout) :: pk
   end subroutine balance

   !> Default of `share_outcomes`: one process evaluated every member.
   subroutine share_outcomes(self, code, busy)
      !> Distributor.
      class(phase1_distributor_type), intent(in) :: self
      !> Outcome of each member (huge() where another process evaluated it).
      integer(i8), intent(inout) :: code(:)
      !> CPU seconds this process spent evaluating its members (counted by distributors that count).
      real(wp), intent(in) :: busy
   end subroutine share_outcomes

   !> Default of `complete_region`: one process holds every particle.
   subroutine complete_region(self, pk, reach)
      !> Distributor.
      class(phase1_distributor_type), intent(in) :: self
      !> This process' packing.
      type(packing_type), intent(inout) :: pk
      !> The new reach (mm).
      real(wp), intent(in) :: reach
   end subroutine complete_region

   !> Default of `to_blocks`: one process holds every particle, in order.
   subroutine to_blocks(self, pk)
      !> Distributor.
      class(phase1_distributor_type), intent(in) :: self
      !> This process' packing.
      type(packing_type), intent(inout) :: pk
   end subroutine to_blocks

   !> Default of `any_over_ranks`: one process.
   subroutine any_over_ranks(self, flags)
      !> Distributor.
      class(phase1_distributor_type), intent(in) :: self
      !> This process' flags; on return true where true on some process.
      logical, intent(inout) :: flags(:)
   end subroutine any_over_ranks

   !> Default of `running_start`: the first block (the sums stay as given).
   subroutine running_start(self, sums)
      !> Distributor.
      class(phase1_distributor_type), intent(in) :: self
      !> On return the sums over the particles of the blocks before this process' one.
      real(wp), intent(inout) :: sums(:)
   end subroutine running_start

   !> Default of `running_end`: the last block (the sums are the totals).
   subroutine running_end(self, sums)
      !> Distributor.
      class(phase1_distributor_type), intent(in) :: self
      !> This process' running sums; on return the totals over all blocks.
      real(wp), intent(inout) :: sums(:)
   end subroutine running_end

   !> Default of `kinds_exchange`: none (every process builds every kind it needs).
   subroutine kinds_exchange(self, kx)
      !> Distributor.
      class(phase1_distributor_type), intent(in) :: self
      !> Exchange (left unallocated).
      class(kind_exchange_type), allocatable, intent(out) :: kx
   end subroutine kinds_exchange

   !> Default of `note_slab`: nothing is recorded.
   subroutine note_slab(self, sieve, nlocal, np, held)
      !> Distributor.
      class(phase1_distributor_type), intent(in) :: self
      !> Sieve that ended.
      integer, intent(in) :: sieve
      !> Particles in this process' cell list, and in the packing (over all processes).
      integer, intent(in) :: nlocal, np
      !> Divided arrays: particles in this process' arrays (0: not divided).
      integer, intent(in) :: held
   end subroutine note_slab

   !> Phase 1: particles nstream + 1 .. nstream + n of the sieve each find their first attempt that
   !> fits the packing as it is (in parallel; each particle draws only from its own stream).
   subroutine speculate(self, n, ap, pk, vg, nstream, dist, window)
      !> Batch.
      class(batch_type), intent(out) :: self
      !> Number of particles.
      integer, intent(in) :: n
      !> Parameters of the sieve.
      type(attempt_params_type), intent(in) :: ap
      !> Packing (frozen during phase 1).
      type(packing_type), intent(in) :: pk
      !> Void grid (void placement).
      type(void_grid_type), intent(in) :: vg
      !> Particles of the sieve before this batch.
      integer, intent(in) :: nstream
      !> Phase 1 spread over processes (absent: this process alone).
      class(phase1_distributor_type), intent(in), optional :: dist
      !> Attempts of the first window of a spatial search (default 1; any value gives the same
      !> attempts).
      integer, intent(in), optional :: window
      real(wp), allocatable :: bx(:, :)
      integer :: b, w
      self%n = n
      allocate (self%at(n), self%br(n), self%alone(n), self%moved_flag(n), self%moved(n), bx(3, n))
      self%moved_flag = .false.
      w = 1
      if (present(window)) w = max(1, window)
      if (present(dist)) then
         call dist%phase1(self%at, ap, pk, vg, nstream, w)
      else
         call run_phase1(self%at, ap, pk, vg, nstream, 1, 1)
      end if
      do b = 1, n
         bx(:, b) = self%at(b)%c
         self%br(b) = self%at(b)%sc * pk%kinds(max(1, self%at(b)%k))%r_out
      end do
      call first_in_reach(bx, self%br, pk%p%box, pk%p%periodic, self%alone)
      self%frozen = pk%mark()
      self%np_frozen = pk%np
   end subroutine speculate

   !> The parallel loop of phase 1 over members first, first + stride, ... of the batch (the
   !> others are left as they are).
   subroutine run_phase1(at, ap, pk, vg, nstream, first, stride)
      !> Attempts of the batch.
      type(attempt_type), intent(inout) :: at(:)
      !> Parameters of the sieve.
      type(attempt_params_type), intent(in) :: ap
      !> Packing (frozen).
      type(packing_type), intent(in) :: pk
      !> Void grid (void placement).
      type(void_grid_type), intent(in) :: vg
      !> Particles of the sieve before this batch.
      integer, intent(in) :: nstream
      !> First member and stride.
      integer, intent(in) :: first, stride
      integer :: b
      !$omp parallel do default(none) shared(at, ap, pk, vg, nstream, first, stride) private(b) schedule(dynamic, 1)
      do b = first, size(at), stride
         block
            type(fit_scratch_type) :: scratch
            call at(b)%start(ap, nstream + b)
            do
               call at(b)%next(ap, pk%kinds, vg)
               if (at(b)%done) exit
               if (pk%fits(at(b)%k, at(b)%c, at(b)%r, at(b)%sc, scratch)) exit
            end do
         end block
      end do
      !$omp end parallel do
   end subroutine run_phase1

   !> The spatial search (see the module's notes) of members `list` of `at`, each from its current
   !> attempt on (started, or hit in phase 2; that attempt is not tested again): on return each is
   !> at its first attempt that fits the whole packing, or done, on every process alike
   !> (collective: every process calls it with the same members). Windows of attempts: `window`
   !> (default 1), then doubling for the members still searching, so that the attempts drawn
   !> past the first fit are at most about as many as those before it.
   subroutine spatial_search(at, list, ap, pk, vg, window, dist)
      !> Attempts.
      type(attempt_type), intent(inout) :: at(:)
      !> Members to search.
      integer, intent(in) :: list(:)
      !> Parameters of the sieve.
      type(attempt_params_type), intent(in) :: ap
      !> This process' packing (local: `packing_type%localize`).
      type(packing_type), intent(in) :: pk
      !> Void grid (void placement).
      type(void_grid_type), intent(in) :: vg
      !> Attempts in the first window (default 1).
      integer, intent(in), optional :: window
      !> Processes.
      class(phase1_distributor_type), intent(in) :: dist
      integer, allocatable :: act(:)
      integer(i8), allocatable :: kfit(:)
      type(attempt_type), allocatable :: saved(:)
      integer :: w, i, j, n, nk
      integer(i8), parameter :: none = huge(1_i8)
      w = 1
      if (present(window)) w = max(1, window)
      act = list
      do while (size(act) > 0)
         n = size(act)
         saved = at(act)
         allocate (kfit(n))
         !$omp parallel do default(none) shared(at, act, ap, pk, vg, kfit, n, w) private(i, j) schedule(dynamic, 1)
         do i = 1, n
            block
               type(fit_scratch_type) :: scratch
               kfit(i) = none
               associate (a => at(act(i)))
                  do j = 1, w
                     call a%next(ap, pk%kinds, vg)
                     if (a%done) exit
                     if (.not. pk%owns(a%c)) cycle
                     if (pk%fits(a%k, a%c, a%r, a%sc, scratch)) then
                        kfit(i) = a%count
                        exit
                     end if
                  end do
               end associate
            end block
         end do
         !$omp end parallel do
         call dist%agree_first(kfit)
         nk = 0
         do i = 1, n
            associate (a => at(act(i)))
               if (kfit(i) < none) then
                  ! another process' attempt fits first: replay the draws to it
                  if (a%count /= kfit(i)) then
                     a = saved(i)
                     do while (a%count < kfit(i))
                        call a%next(ap, pk%kinds, vg)
                     end do
                  end if
               else if (.not. a%done) then
                  ! no fit in this window on any process (every process drew the whole window)
                  nk = nk + 1
                  act(nk) = act(i)
               end if
            end associate
         end do
         act = act(:nk)
         deallocate (kfit)
         w = min(2 * w, 2**20)
      end do
   end subroutine spatial_search

   !> Phase 2 for particle b (after every earlier particle of the batch was settled and parked or
   !> not): its attempt is re-checked against the particles parked since phase 1 when it may meet
   !> one, and if it overlaps, its sequence continues against the whole packing.
   subroutine settle(self, b, ap, pk, vg, scratch, dist, window)
      !> Batch.
      class(batch_type), intent(inout) :: self
      !> Particle of the batch.
      integer, intent(in) :: b
      !> Parameters of the sieve.
      type(attempt_params_type), intent(in) :: ap
      !> Packing.
      type(packing_type), intent(in) :: pk
      !> Void grid (void placement).
      type(void_grid_type), intent(in) :: vg
      !> Scratch for the overlap tests.
      type(fit_scratch_type), intent(inout) :: scratch
      !> Processes (a spatial one searches the continuation over all; collective then).
      class(phase1_distributor_type), intent(in), optional :: dist
      !> First window of that search (default 1).
      integer, intent(in), optional :: window
      associate (a => self%at(b))
         if (a%done) return
         if (self%alone(b)) then
            if (.not. near_moved(self, b, pk)) return
         end if
         ! every process holds the particles parked since phase 1 (`localize` runs after the
         ! batch), so every process decides this alike
         if (pk%fits(a%k, a%c, a%r, a%sc, scratch, since=self%frozen)) return
         self%moved_flag(b) = .true.
         if (present(dist)) then
            if (dist%spatial) then
               call spatial_search(self%at, [b], ap, pk, vg, window, dist)
               return
            end if
         end if
         do
            call a%next(ap, pk%kinds, vg)
            if (a%done) exit
            if (pk%fits(a%k, a%c, a%r, a%sc, scratch)) exit
         end do
      end associate
   end subroutine settle

   !> Record that particle b of the batch was parked (at its settled pose).
   subroutine accept(self, b)
      !> Batch.
      class(batch_type), intent(inout) :: self
      !> Particle of the batch.
      integer, intent(in) :: b
      if (.not. self%moved_flag(b)) return
      self%nmoved = self%nmoved + 1
      self%moved(self%nmoved) = b
   end subroutine accept

   !> True when the bounding sphere of batch particle bb (phase-1 pose) meets that of a particle
   !> of the batch parked at another pose than its phase-1 one.
   logical function near_moved(bt, bb, pk) result(near)
      type(batch_type), intent(in) :: bt
      integer, intent(in) :: bb
      type(packing_type), intent(in) :: pk
      integer :: i, mv
      real(wp) :: d(3), lim
      near = .false.
      do i = 1, bt%nmoved
         mv = bt%moved(i)
         d = bt%at(mv)%c - bt%at(bb)%c
         if (pk%p%periodic) d = d - pk%p%box * anint(d / pk%p%box)
         lim = bt%br(bb) + bt%at(mv)%sc * pk%kinds(bt%at(mv)%k)%r_out
         if (sum(d**2) < lim * lim) then
            near = .true.
            return
         end if
      end do
   end function near_moved

   !> Size of the next batch. Any size gives the same model, so it follows the machine: about
   !> `batch_seconds` of phase 1 (few synchronisations, which matters most when the cores are
   !> shared with other jobs), changing by at most a factor 2 per batch, and not much beyond the
   !> particles the sieve still needs (speculation past its end is wasted work).
   pure integer function next_batch(now, seconds, missing, vol_sieve, count_sieve, nthr) result(nb)
      !> Size of the batch that just ran.
      integer, intent(in) :: now
      !> Its phase-1 time (s).
      real(wp), intent(in) :: seconds
      !> Volume the sieve still misses and volume parked in it (mm^3).
      real(wp), intent(in) :: missing, vol_sieve
      !> Particles parked in the sieve; threads.
      integer, intent(in) :: count_sieve, nthr
      real(wp), parameter :: batch_seconds = 0.05_wp
      integer, parameter :: max_per_thread = 1024
      real(wp) :: f, need
      f = 2.0_wp
      if (seconds > 0.0_wp) f = max(0.5_wp, min(2.0_wp, batch_seconds / seconds))
      nb = max(nthr, min(max_per_thread * nthr, nint(now * f)))
      if (count_sieve > 0) then
         need = max(0.0_wp, missing) / (vol_sieve / count_sieve)
         nb = max(nthr, min(nb, int(min(need, real(huge(1) / 2, wp))) + nthr))
      end if
   end function next_batch

   !> For each sphere (centres x(:, i) in the box, radii r(i)), whether no sphere of smaller index
   !> meets it (nearest periodic image): spheres hashed into cells at least 2 max(r) wide, the 27
   !> cells around each searched in parallel.
   subroutine first_in_reach(x, r, box, periodic, alone)
      !> Centres (3, n).
      real(wp), intent(in) :: x(:, :)
      !> Radii.
      real(wp), intent(in) :: r(:)
      !> Box edges.
      real(wp), intent(in) :: box(3)
      !> Periodic boundaries.
      logical, intent(in) :: periodic
      !> No sphere of smaller index meets sphere i.
      logical, intent(out) :: alone(:)
      integer, allocatable :: cell(:, :), first(:), item(:), key(:)
      integer :: n, nc(3), nbucket, i, d
      ! fewer spheres than this are searched by the calling thread alone
      integer, parameter :: parallel_min = 8192
      real(wp) :: h(3)
      n = size(r)
      alone = .true.
      if (n < 2) return
      nc = max(1, int(box / max(2.0_wp * maxval(r), tiny(1.0_wp))))
      nc = min(nc, 1024)
      h = box / nc
      nbucket = 2**ceiling(log(real(2 * n, wp)) / log(2.0_wp))
      allocate (cell(3, n), key(n), first(nbucket + 1), item(n))
      do i = 1, n
         do d = 1, 3
            cell(d, i) = min(nc(d) - 1, max(0, int(x(d, i) / h(d))))
         end do
         key(i) = bucket_of(cell(:, i), nbucket)
      end do
      ! counting sort by bucket, indices ascending within a bucket
      first = 0
      do i = 1, n
         first(key(i) + 1) = first(key(i) + 1) + 1
      end do
      do i = 2, nbucket + 1
         first(i) = first(i) + first(i - 1)
      end do
      do i = 1, n
         first(key(i)) = first(key(i)) + 1
         item(first(key(i))) = i
      end do
      ! first(k) now ends bucket k: bucket k is item(first(k - 1) + 1 : first(k)), bucket 1 from 1
      if (n < parallel_min) then
         ! a batch of fine grains (void placement caps batches at 64): a parallel region would cost
         ! more than the search, and on a loaded machine its barrier spins (docs/performance-notes.md)
         do i = 2, n
            alone(i) = nothing_near(i, x, r, box, periodic, nc, nbucket, cell, first, item)
         end do
         return
      end if
      !$omp parallel do default(none) shared(n, x, r, box, periodic, nc, nbucket, cell, first, item, alone) &
      !$omp& private(i) schedule(static)
      do i = 2, n
         alone(i) = nothing_near(i, x, r, box, periodic, nc, nbucket, cell, first, item)
      end do
      !$omp end parallel do
   end subroutine first_in_reach

   !> Hash bucket (1..nbucket, a power of 2) of a cell.
   pure integer function bucket_of(c, nbucket) result(k)
      integer, intent(in) :: c(3), nbucket
      k = 1 + iand(c(1) + 1031 * (c(2) + 1031 * c(3)), nbucket - 1)
   end function bucket_of

   !> No sphere of smaller index than i meets sphere i (first_in_reach's hash).
   pure logical function nothing_near(i, x, r, box, periodic, nc, nbucket, cell, first, item) result(ok)
      integer, intent(in) :: i, nc(3), nbucket, cell(:, :), first(:), item(:)
      real(wp), intent(in) :: x(:, :), r(:), box(3)
      logical, intent(in) :: periodic
      integer :: d1, d2, d3, c(3), k, m, j, lo
      real(wp) :: dx(3)
      ok = .true.
      do d3 = -1, 1
         do d2 = -1, 1
            do d1 = -1, 1
               c = cell(:, i) + [d1, d2, d3]
               if (periodic) then
                  c = modulo(c, nc)
               else if (any(c < 0 .or. c >= nc)) then
                  cycle
               end if
               k = bucket_of(c, nbucket)
               lo = 1
               if (k > 1) lo = first(k - 1) + 1
               do m = lo, first(k)
                  j = item(m)
                  if (j >= i) exit
                  dx = x(:, j) - x(:, i)
                  if (periodic) dx = dx - box * anint(dx / box)
                  if (sum(dx**2) < (r(i) + r(j))**2) then
                     ok = .false.
                     return
                  end if
               end do
            end do
         end do
      end do
   end function nothing_near
end module anm_parking_scheduler
