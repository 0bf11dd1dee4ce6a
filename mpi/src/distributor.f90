!> Phase 1 of the parking's batches over MPI processes, in one of two modes:
!>
!> - spatial (the default for RSA): process r owns slab r of nranks equal slabs along x and its
!>   cell list holds only the particles in reach of the slab (anm_parking_packing's slabs). Every
!>   process draws every member's attempts in windows and tests those centred in its slab; one
!>   MPI_Allreduce(MIN) of 8 bytes per member and window gives each member's first fitting
!>   attempt (anm_parking_scheduler's `spatial_search`). Hit members of phase 2 continue the same
!>   way, one member per search.
!> - replicated (`spatial = .false.`; the dense strategy, or `anm run --replicated`): every process
!>   holds the whole packing; member b of a batch runs phase 1 on process mod(b - 1, nranks) (with
!>   its threads), and the attempts (random stream state, counters, pose, count) are gathered to
!>   every process with one MPI_Allgatherv.
!>
!> Phase 2 (in-order re-check and accept) then runs identically on every process, so every
!> process parks the serial model (anm_parking_scheduler: any batch composition gives the serial
!> result).
!>
!> With `count = .true.` it counts what it communicates (`comm_stats_type`: per batch its sieve
!> and the bytes gathered to every process, the batch-clock reductions) and `write_comm_stats`
!> prints them per sieve with the peak memory of every process (`anm run FILE.nml --comm-stats`).
!>
!> Usage:
!>     call new_mpi_distributor(dist, MPI_COMM_WORLD, omp_get_max_threads())
!>     call run_job(path, output_unit, error_unit, error, threads, dist=dist)
module anm_mpi_distributor
   use, intrinsic :: iso_fortran_env, only: int8, int64, error_unit
   use anm_core_kinds, only: wp
   use anm_parking_attempts, only: attempt_type, attempt_params_type
   use anm_parking_packing, only: packing_type, near_slab
   use anm_parking_void_grid, only: void_grid_type
   use anm_parking_scheduler, only: phase1_distributor_type, run_phase1, spatial_search
   use anm_parking_kinds, only: kind_exchange_type
   use anm_mpi_kinds, only: mpi_kinds_type, new_mpi_kinds
   use anm_io_hdf5, only: block_start
   use mpi_f08, only: MPI_Comm, MPI_Allgather, MPI_Allgatherv, MPI_Allreduce, MPI_Comm_rank, MPI_Comm_size, MPI_BYTE, &
                      MPI_DOUBLE_PRECISION, MPI_INTEGER, MPI_INTEGER8, MPI_MAX, MPI_SUM, MPI_MIN, MPI_Wtime, &
                      MPI_IN_PLACE, MPI_Alltoall, MPI_Alltoallv, MPI_LOGICAL, MPI_LOR, MPI_Send, MPI_Recv, &
                      MPI_Bcast, MPI_STATUS_IGNORE, MPI_Comm_split_type, MPI_COMM_TYPE_SHARED, MPI_INFO_NULL, &
                      MPI_Comm_free, MPI_Datatype, MPI_Type_contiguous, MPI_Type_commit, MPI_Type_free, &
                      MPI_Abort
   implicit none
   private

   public :: mpi_distributor_type, new_mpi_distributor, comm_stats_type, write_comm_stats, peak_memory_kb

   !> What the distributor communicated: per batch the sieve and the bytes of the attempts gathered
   !> to every process (members x attempt size), and the number of batch-clock reductions.
   type :: comm_stats_type
      !> Batches recorded.
      integer :: nbatch = 0
      !> Per batch: sieve, members, bytes gathered to every process.
      integer, allocatable :: sieve(:), members(:)
      integer(int64), allocatable :: bytes(:)
      !> Allreduce calls of the batch clock (8 bytes each).
      integer(int64) :: reductions = 0
      !> Bytes of one attempt.
      integer :: attempt_bytes = 0
      !> Spatial mode: the first-fit reductions (windows) and their bytes, per run.
      integer(int64) :: windows = 0, window_bytes = 0
      !> The mode the batches ran in (the dense strategy runs replicated whatever was asked).
      logical :: slabs = .false.
      !> Spatial mode, per sieve (at its end): particles in this process' cell list and in the
      !> packing (0: not recorded).
      integer :: slab_local(64) = 0, slab_total(64) = 0
      !> Divided particle arrays, per sieve (at its end): the particles this process holds (0:
      !> not divided); the exchanges that completed the arrays (slabs moved, reach grown) and the
      !> bytes this process received in them; the bytes it received when the particles went to
      !> their blocks of global ids for the output.
      integer :: held(64) = 0
      integer(int64) :: exchanges = 0, exchange_bytes = 0, block_bytes = 0
      !> This process: phase 1's CPU time (all its threads) and wall time, and the wall time in
      !> the gathers (s).
      real(wp) :: phase1_cpu = 0.0_wp, phase1_wall = 0.0_wp, gather_wall = 0.0_wp
      !> The dense strategy's sweeps: batches of trials shared (one reduction each), trials, bytes
      !> reduced by each process, wall time in those reductions and CPU time this process spent
      !> evaluating its share of the trials (s).
      integer(int64) :: sweep_batches = 0, sweep_trials = 0, sweep_bytes = 0
      real(wp) :: sweep_wall = 0.0_wp, sweep_cpu = 0.0_wp
   end type comm_stats_type

   !> The load balance of the slabs: this process' busy time (its share of the spatial searches,
   !> outside the reductions) since the last balance, and when the slabs last moved.
   type :: balance_state_type
      !> Busy seconds since the last balance; the clock at the end of the last reduction.
      real(wp) :: busy = 0.0_wp, mark = 0.0_wp
      !> Batches since the last balance; times the slabs moved; wall seconds of the last move
      !> (its cell-list rebuild), and busy seconds since then.
      integer :: batches = 0, moves = 0
      real(wp) :: move_cost = 0.0_wp, since_move = 0.0_wp
      !> Imbalance (largest over mean busy time) at the first and the last check.
      real(wp) :: first_ratio = 0.0_wp, last_ratio = 0.0_wp
      !> Slab bounds after the last move (mm), process 0 .. n - 1's lower ones and the box edge.
      real(wp), allocatable :: bounds(:)
      !> Batches between checks; a move at every check whatever the times (the tests set this
      !> with ANM_MPI_BALANCE_EVERY=N: a check every N batches, always a move).
      integer :: every = 32
      logical :: always = .false.
   end type balance_state_type

   !> Phase 1 over the processes of a communicator.
   type, extends(phase1_distributor_type) :: mpi_distributor_type
      !> Communicator (this process' rank and the number of processes are the parent's).
      type(MPI_Comm) :: comm
      !> Counters (allocated when counting; a pointer, so that the collective calls, which take
      !> the distributor as intent(in), can count).
      type(comm_stats_type), pointer :: stats => null()
      !> Load balance of the slabs (a pointer for the same reason).
      type(balance_state_type), pointer :: bal => null()
   contains
      procedure :: phase1
      procedure :: agree
      procedure :: agree_first
      procedure :: note_slab
      procedure :: kinds_exchange
      procedure :: balance
      procedure :: share_outcomes
      procedure :: complete_region
      procedure :: to_blocks
      procedure :: any_over_ranks
      procedure :: running_start
      procedure :: running_end
   end type mpi_distributor_type

   !> Doubles per particle sent between processes: global id, centre, rotation, scale, kind, sieve
   !> (the integers are exact in a double).
   integer, parameter :: particle_doubles = 16

contains

   !> A distributor over `comm` (collective): `threads` are this process' threads; the batches are
   !> sized for the threads of all processes; rank 0 writes.
   subroutine new_mpi_distributor(dist, comm, threads, count, replicated)
      !> Distributor.
      type(mpi_distributor_type), intent(out) :: dist
      !> Communicator.
      type(MPI_Comm), intent(in) :: comm
      !> Threads of this process.
      integer, intent(in) :: threads
      !> Count what is communicated (comm_stats_type).
      logical, intent(in), optional :: count
      !> Replicated data instead of slabs (default: slabs, the spatial decomposition).
      logical, intent(in), optional :: replicated
      character(len=32) :: env
      integer :: stat, every
      type(MPI_Comm) :: node
      dist%comm = comm
      if (present(count)) then
         if (count) then
            allocate (dist%stats)
            allocate (dist%stats%sieve(64), dist%stats%members(64), dist%stats%bytes(64))
         end if
      end if
      call MPI_Comm_rank(comm, dist%rank)
      call MPI_Comm_size(comm, dist%nranks)
      call MPI_Allreduce(max(1, threads), dist%workers, 1, MPI_INTEGER, MPI_SUM, comm)
      ! the processes that share this machine's memory
      call MPI_Comm_split_type(comm, MPI_COMM_TYPE_SHARED, dist%rank, MPI_INFO_NULL, node)
      call MPI_Comm_size(node, dist%ranks_on_node)
      call MPI_Comm_free(node)
      dist%writer = dist%rank == 0
      dist%spatial = dist%nranks > 1
      if (present(replicated)) dist%spatial = dist%spatial .and. .not. replicated
      dist%nslab = dist%nranks
      dist%slab = dist%rank
      allocate (dist%bal)
      call get_environment_variable("ANM_MPI_BALANCE_EVERY", env, status=stat)
      if (stat == 0) then
         read (env, *, iostat=stat) every
         if (stat == 0 .and. every >= 1) then
            dist%bal%every = every
            dist%bal%always = .true.
         end if
      end if
   end subroutine new_mpi_distributor

   !> Phase 1 of a batch: this process' members (rank + 1, rank + 1 + nranks, ...), then every
   !> member's attempt gathered to every process (collective).
   subroutine phase1(self, at, ap, pk, vg, nstream, window)
      !> Distributor.
      class(mpi_distributor_type), intent(in) :: self
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
      integer(int8), allocatable :: mine(:), all(:)
      integer, allocatable :: counts(:), displs(:)
      integer :: n, r, bytes, i, b
      real :: c0, c1
      real(wp) :: w0, w1
      n = size(at)
      ! every process holds the same binary: an attempt travels as its bytes
      bytes = storage_size(at(1)) / 8
      if (associated(self%stats)) then
         call record_batch(self%stats, ap%sieve, n, merge(0, bytes, self%spatial), self%nranks)
         self%stats%slabs = self%spatial
         call cpu_time(c0)
         w0 = MPI_Wtime()
      end if
      if (self%spatial) then
         ! busy time starts now (the phase 2 of the last batch was the same on every process)
         self%bal%mark = MPI_Wtime()
         do b = 1, n
            call at(b)%start(ap, nstream + b)
         end do
         call spatial_search(at, [(b, b=1, n)], ap, pk, vg, window, self)
         if (associated(self%stats)) then
            call cpu_time(c1)
            self%stats%phase1_cpu = self%stats%phase1_cpu + (c1 - c0)
            self%stats%phase1_wall = self%stats%phase1_wall + (MPI_Wtime() - w0)
         end if
         return
      end if
      call run_phase1(at, ap, pk, vg, nstream, self%rank + 1, self%nranks)
      if (associated(self%stats)) then
         call cpu_time(c1)
         w1 = MPI_Wtime()
         self%stats%phase1_cpu = self%stats%phase1_cpu + (c1 - c0)
         self%stats%phase1_wall = self%stats%phase1_wall + (w1 - w0)
      end if
      if (self%nranks == 1) return
      allocate (counts(0:self%nranks - 1), displs(0:self%nranks - 1))
      do r = 0, self%nranks - 1
         counts(r) = members(n, r, self%nranks)
      end do
      displs(0) = 0
      do r = 1, self%nranks - 1
         displs(r) = displs(r - 1) + counts(r - 1)
      end do
      allocate (mine(counts(self%rank) * bytes), all(n * bytes))
      do i = 1, counts(self%rank)
         b = self%rank + 1 + (i - 1) * self%nranks
         mine((i - 1) * bytes + 1:i * bytes) = transfer(at(b), mine)
      end do
      if (associated(self%stats)) w0 = MPI_Wtime()
      call MPI_Allgatherv(mine, counts(self%rank) * bytes, MPI_BYTE, all, counts * bytes, displs * bytes, MPI_BYTE, &
                          self%comm)
      if (associated(self%stats)) self%stats%gather_wall = self%stats%gather_wall + (MPI_Wtime() - w0)
      ! rank r's members are r + 1, r + 1 + nranks, ... in order
      do r = 0, self%nranks - 1
         do i = 1, counts(r)
            b = r + 1 + (i - 1) * self%nranks
            at(b) = transfer(all((displs(r) + i - 1) * bytes + 1:(displs(r) + i) * bytes), at(b))
         end do
      end do
   end subroutine phase1

   !> The largest x over the processes (collective).
   function agree(self, x) result(y)
      !> Distributor.
      class(mpi_distributor_type), intent(in) :: self
      !> This process' value.
      real(wp), intent(in) :: x
      real(wp) :: y
      call MPI_Allreduce(x, y, 1, MPI_DOUBLE_PRECISION, MPI_MAX, self%comm)
      if (associated(self%stats)) self%stats%reductions = self%stats%reductions + 1
   end function agree

   !> The smallest of each value over the processes, in place (collective): the first fitting
   !> attempt of each member of a spatial search's window.
   subroutine agree_first(self, k)
      !> Distributor.
      class(mpi_distributor_type), intent(in) :: self
      !> This process' values; on return the smallest over the processes.
      integer(int64), intent(inout) :: k(:)
      real(wp) :: wait
      if (self%nranks == 1) return
      self%bal%busy = self%bal%busy + (MPI_Wtime() - self%bal%mark)
      wait = min_over_ranks(self, k)
      self%bal%mark = MPI_Wtime()
      if (associated(self%stats)) then
         self%stats%gather_wall = self%stats%gather_wall + wait
         self%stats%windows = self%stats%windows + 1
         self%stats%window_bytes = self%stats%window_bytes + 8_int64 * size(k)
         if (self%stats%nbatch > 0) self%stats%bytes(self%stats%nbatch) = self%stats%bytes(self%stats%nbatch) &
                                                                           + 8_int64 * size(k)
      end if
   end subroutine agree_first

   !> The outcomes of a batch of trials evaluated in shares (the dense strategy's sweeps;
   !> collective): the same reduction as `agree_first` (MPI_Allreduce MIN, 8 bytes per member),
   !> counted apart.
   subroutine share_outcomes(self, code, busy)
      !> Distributor.
      class(mpi_distributor_type), intent(in) :: self
      !> Outcome of each member, huge(code) where this process did not evaluate it; on return the
      !> smallest over the processes, the evaluating process' value.
      integer(int64), intent(inout) :: code(:)
      !> CPU seconds this process spent evaluating its members.
      real(wp), intent(in) :: busy
      real(wp) :: wait
      if (self%nranks == 1) return
      wait = min_over_ranks(self, code)
      if (associated(self%stats)) then
         self%stats%sweep_wall = self%stats%sweep_wall + wait
         self%stats%sweep_cpu = self%stats%sweep_cpu + busy
         self%stats%sweep_batches = self%stats%sweep_batches + 1
         self%stats%sweep_trials = self%stats%sweep_trials + size(code)
         self%stats%sweep_bytes = self%stats%sweep_bytes + 8_int64 * size(code)
      end if
   end subroutine share_outcomes

   !> The smallest of each value over the processes, in place (collective); the wall seconds the
   !> reduction took.
   function min_over_ranks(self, k) result(seconds)
      class(mpi_distributor_type), intent(in) :: self
      integer(int64), intent(inout) :: k(:)
      real(wp) :: seconds
      seconds = MPI_Wtime()
      call MPI_Allreduce(MPI_IN_PLACE, k, size(k), MPI_INTEGER8, MPI_MIN, self%comm)
      seconds = MPI_Wtime() - seconds
   end function min_over_ranks

   !> Every 32 batches (collective): when the processes' busy times differ by more
   !> than 10 % (largest over mean), the slab bounds move to where the work, taken as uniform
   !> along x within each slab, splits evenly (70 % of the way, against oscillation), and each
   !> process rebuilds its cell list (`packing_type%set_slab`). A move waits until the busy time
   !> since the last one is 20 times what that move's rebuild took. The bounds are computed alike
   !> on every process from the gathered times; the model does not depend on them.
   subroutine balance(self, pk)
      !> Distributor.
      class(mpi_distributor_type), intent(in) :: self
      !> This process' packing.
      type(packing_type), intent(inout) :: pk
      real(wp) :: t(0:self%nranks - 1), b(0:self%nranks), nb(0:self%nranks), cum(0:self%nranks)
      real(wp) :: lo, hi, total, target, w0, ratio
      integer :: r, i, n
      if (.not. self%spatial .or. self%nranks == 1) return
      associate (bl => self%bal)
         bl%batches = bl%batches + 1
         if (bl%batches < bl%every) return
         n = self%nranks
         call MPI_Allgather(bl%busy, 1, MPI_DOUBLE_PRECISION, t, 1, MPI_DOUBLE_PRECISION, self%comm)
         bl%batches = 0
         bl%busy = 0.0_wp
         total = sum(t)
         bl%since_move = bl%since_move + total / n
         ratio = maxval(t) / max(1.0e-12_wp, total / n)
         if (bl%first_ratio == 0.0_wp) bl%first_ratio = ratio
         bl%last_ratio = ratio
         if (.not. bl%always .and. (ratio < 1.1_wp .or. bl%since_move < 20.0_wp * bl%move_cost)) return
         call pk%slab_bounds(lo, hi)
         call MPI_Allgather(lo, 1, MPI_DOUBLE_PRECISION, b, 1, MPI_DOUBLE_PRECISION, self%comm)
         b(0) = 0.0_wp
         b(n) = pk%p%box(1)
         t = max(t, 1.0e-9_wp * total)
         cum(0) = 0.0_wp
         do r = 0, n - 1
            cum(r + 1) = cum(r) + t(r)
         end do
         nb = b
         i = 0
         do r = 1, n - 1
            target = cum(n) * r / n
            do while (i < n - 1 .and. cum(i + 1) < target)
               i = i + 1
            end do
            nb(r) = b(i) + (target - cum(i)) / t(i) * (b(i + 1) - b(i))
            nb(r) = b(r) + 0.7_wp * (nb(r) - b(r))
         end do
         w0 = MPI_Wtime()
         if (allocated(pk%gid)) then
            ! divided arrays: the particles of the slab's new part come from their owners
            call exchange_region(self, pk, nb, pk%reach)
         else
            call pk%set_slab(nb(self%rank), nb(self%rank + 1))
         end if
         bl%move_cost = MPI_Wtime() - w0
         call MPI_Allreduce(MPI_IN_PLACE, bl%move_cost, 1, MPI_DOUBLE_PRECISION, MPI_MAX, self%comm)
         bl%since_move = 0.0_wp
         bl%moves = bl%moves + 1
         bl%bounds = nb
      end associate
   end subroutine balance

   !> Divided particle arrays (collective): every process' arrays made complete for the reach r
   !> (larger than their `held_reach`; the slabs stay).
   subroutine complete_region(self, pk, reach)
      !> Distributor.
      class(mpi_distributor_type), intent(in) :: self
      !> This process' packing.
      type(packing_type), intent(inout) :: pk
      !> The new reach (mm).
      real(wp), intent(in) :: reach
      real(wp) :: b(0:self%nranks), lo, hi
      if (.not. allocated(pk%gid)) return
      call pk%slab_bounds(lo, hi)
      call MPI_Allgather(lo, 1, MPI_DOUBLE_PRECISION, b, 1, MPI_DOUBLE_PRECISION, self%comm)
      b(self%nranks) = pk%p%box(1)
      call exchange_region(self, pk, b, reach)
   end subroutine complete_region

   !> Divided particle arrays (collective): each process sends every particle it owns (centre in
   !> its slab as the bounds now are) to every other process q whose new slab [nb(q), nb(q + 1))
   !> it can reach with the reach r (`near_slab`), one MPI_Alltoallv; then each process takes
   !> its new bounds and reach and adds what it received (`take_particles`). Every particle
   !> within reach of a new slab is owned by some process, which holds it: the arrays are
   !> complete for the new slabs and reach.
   subroutine exchange_region(self, pk, nb, reach)
      class(mpi_distributor_type), intent(in) :: self
      type(packing_type), intent(inout) :: pk
      real(wp), intent(in) :: nb(0:), reach
      integer :: nsend(0:self%nranks - 1), nrecv(0:self%nranks - 1), sdis(0:self%nranks - 1), rdis(0:self%nranks - 1)
      real(wp), allocatable :: sbuf(:, :), rbuf(:, :), x(:, :), rr(:, :, :), sc(:)
      integer, allocatable :: g(:), kn(:), sv(:)
      integer :: i, q, n, k, nr, pass
      n = self%nranks
      ! which particles go where (each owned one to every other slab it can reach): counted, then
      ! packed
      do pass = 1, 2
         nsend = 0
         do i = 1, pk%np
            if (.not. pk%owns(pk%center(:, i))) cycle
            do q = 0, n - 1
               if (q == self%rank) cycle
               if (.not. near_slab(pk%p, nb(q), nb(q + 1), q, reach, pk%center(1, i), pk%rho(i))) cycle
               if (pass == 2) call pack_particle(pk, i, sbuf(:, sdis(q) + nsend(q) + 1))
               nsend(q) = nsend(q) + 1
            end do
         end do
         if (pass == 1) then
            call displacements(nsend, sdis)
            allocate (sbuf(particle_doubles, sum(nsend)))
         end if
      end do
      call MPI_Alltoall(nsend, 1, MPI_INTEGER, nrecv, 1, MPI_INTEGER, self%comm)
      call displacements(nrecv, rdis)
      nr = sum(nrecv)
      allocate (rbuf(particle_doubles, nr))
      call alltoallv_particles(self, sbuf, nsend, sdis, rbuf, nrecv, rdis)
      deallocate (sbuf)
      if (associated(self%stats)) then
         self%stats%exchanges = self%stats%exchanges + 1
         self%stats%exchange_bytes = self%stats%exchange_bytes + 8_int64 * particle_doubles * nr
      end if
      pk%slab_lo = nb(self%rank)
      pk%slab_hi = nb(self%rank + 1)
      pk%reach = reach
      allocate (g(nr), kn(nr), sv(nr), x(3, nr), rr(3, 3, nr), sc(nr))
      do k = 1, nr
         call unpack_particle(rbuf(:, k), g(k), x(:, k), rr(:, :, k), sc(k), kn(k), sv(k))
      end do
      deallocate (rbuf)
      call pk%take_particles(g, x, rr, sc, kn, sv)
   end subroutine exchange_region

   !> Divided particle arrays, after the parking (collective): every particle goes from the
   !> process that owns it (centre in its slab) to the process of its block of global ids, block
   !> r = ids N r / n + 1 .. N (r + 1) / n (N particles, n processes; the parallel writer's
   !> blocks), one MPI_Alltoallv; the packing then holds its block in order (no cell list).
   subroutine to_blocks(self, pk)
      !> Distributor.
      class(mpi_distributor_type), intent(in) :: self
      !> This process' packing.
      type(packing_type), intent(inout) :: pk
      integer :: nsend(0:self%nranks - 1), nrecv(0:self%nranks - 1), sdis(0:self%nranks - 1), rdis(0:self%nranks - 1)
      integer, allocatable :: to(:)
      real(wp), allocatable :: sbuf(:, :), rbuf(:, :)
      integer :: i, q, n, k, nr, g, lo, hi
      integer(int64) :: ntot
      if (.not. allocated(pk%gid)) return
      n = self%nranks
      ntot = pk%ntotal
      allocate (to(pk%np))
      nsend = 0
      do i = 1, pk%np
         to(i) = -1
         if (.not. pk%owns(pk%center(:, i))) cycle
         to(i) = block_of(pk%gid(i))
         nsend(to(i)) = nsend(to(i)) + 1
      end do
      call MPI_Alltoall(nsend, 1, MPI_INTEGER, nrecv, 1, MPI_INTEGER, self%comm)
      call displacements(nsend, sdis)
      call displacements(nrecv, rdis)
      ! the cell list goes first: the send buffer takes its place
      call pk%release()
      allocate (sbuf(particle_doubles, sum(nsend)))
      nsend = 0
      do i = 1, pk%np
         q = to(i)
         if (q < 0) cycle
         call pack_particle(pk, i, sbuf(:, sdis(q) + nsend(q) + 1))
         nsend(q) = nsend(q) + 1
      end do
      deallocate (to)
      deallocate (pk%center, pk%rot, pk%scale, pk%rho, pk%kind_of, pk%sieve, pk%gid, pk%record)
      allocate (rbuf(particle_doubles, sum(nrecv)))
      call alltoallv_particles(self, sbuf, nsend, sdis, rbuf, nrecv, rdis)
      deallocate (sbuf)
      nr = sum(nrecv)
      if (associated(self%stats)) self%stats%block_bytes = 8_int64 * particle_doubles * nr
      lo = int(block_start(ntot, self%rank, n))
      hi = int(block_start(ntot, self%rank + 1, n))
      ! every particle has exactly one owner: a block short or long is a bug, not a user's error
      if (nr /= hi - lo) then
         write (error_unit, '(a,i0,a,i0,a,i0)') "anm: internal error: rank ", self%rank, " received ", nr, &
            " particles for its block of ", hi - lo
         call MPI_Abort(self%comm, 70)
      end if
      allocate (pk%center(3, hi - lo), pk%rot(3, 3, hi - lo), pk%scale(hi - lo), pk%rho(hi - lo), pk%kind_of(hi - lo), &
                pk%sieve(hi - lo), pk%gid(hi - lo), pk%record(hi - lo))
      pk%record = 0
      do k = 1, nr
         g = nint(rbuf(1, k))
         i = g - lo
         call unpack_particle(rbuf(:, k), pk%gid(i), pk%center(:, i), pk%rot(:, :, i), &
                              pk%scale(i), pk%kind_of(i), pk%sieve(i))
         pk%rho(i) = pk%scale(i) * pk%kinds(pk%kind_of(i))%r_out
      end do
      pk%np = hi - lo
   contains
      !> The process of global id gg's block.
      integer function block_of(gg) result(r)
         integer, intent(in) :: gg
         r = int((int(gg - 1, int64) * n) / ntot)
         ! the blocks' bounds round down: step to the block that holds gg
         do while (r > 0 .and. gg <= block_start(ntot, r, n))
            r = r - 1
         end do
         do while (r < n - 1 .and. gg > block_start(ntot, r + 1, n))
            r = r + 1
         end do
      end function block_of
   end subroutine to_blocks

   !> Whether each entry is true on some process, in place (collective).
   subroutine any_over_ranks(self, flags)
      !> Distributor.
      class(mpi_distributor_type), intent(in) :: self
      !> This process' flags; on return true where true on some process.
      logical, intent(inout) :: flags(:)
      if (self%nranks == 1) return
      call MPI_Allreduce(MPI_IN_PLACE, flags, size(flags), MPI_LOGICAL, MPI_LOR, self%comm)
   end subroutine any_over_ranks

   !> Sums in the particles' global order (collective with `running_end`): the sums over the blocks
   !> before this process' one, received from the process before it.
   subroutine running_start(self, sums)
      !> Distributor.
      class(mpi_distributor_type), intent(in) :: self
      !> On return the sums over the blocks before this process' one (process 0: unchanged).
      real(wp), intent(inout) :: sums(:)
      if (self%rank > 0) call MPI_Recv(sums, size(sums), MPI_DOUBLE_PRECISION, self%rank - 1, 7, self%comm, &
                                       MPI_STATUS_IGNORE)
   end subroutine running_start

   !> Sums in the particles' global order (collective with `running_start`): passed on to the next
   !> process; the last one's are the totals, given to every process.
   subroutine running_end(self, sums)
      !> Distributor.
      class(mpi_distributor_type), intent(in) :: self
      !> This process' running sums; on return the totals.
      real(wp), intent(inout) :: sums(:)
      if (self%rank < self%nranks - 1) call MPI_Send(sums, size(sums), MPI_DOUBLE_PRECISION, self%rank + 1, 7, &
                                                     self%comm)
      call MPI_Bcast(sums, size(sums), MPI_DOUBLE_PRECISION, self%nranks - 1, self%comm)
   end subroutine running_end

   !> The particles of sbuf (nsend(q) of them from column sdis(q) + 1 for process q) to the
   !> others, rbuf receiving nrecv(q) from process q at column rdis(q) + 1 (collective; one
   !> MPI_Alltoallv with a datatype of one particle, so that the counts are particles).
   subroutine alltoallv_particles(self, sbuf, nsend, sdis, rbuf, nrecv, rdis)
      class(mpi_distributor_type), intent(in) :: self
      real(wp), intent(in) :: sbuf(:, :)
      integer, intent(in) :: nsend(0:), sdis(0:), nrecv(0:), rdis(0:)
      real(wp), intent(inout) :: rbuf(:, :)
      type(MPI_Datatype) :: particle
      call MPI_Type_contiguous(particle_doubles, MPI_DOUBLE_PRECISION, particle)
      call MPI_Type_commit(particle)
      call MPI_Alltoallv(sbuf, nsend, sdis, particle, rbuf, nrecv, rdis, particle, self%comm)
      call MPI_Type_free(particle)
   end subroutine alltoallv_particles

   !> Particle i of the packing as `particle_doubles` doubles.
   subroutine pack_particle(pk, i, buf)
      type(packing_type), intent(in) :: pk
      integer, intent(in) :: i
      real(wp), intent(out) :: buf(particle_doubles)
      buf(1) = real(pk%gid(i), wp)
      buf(2:4) = pk%center(:, i)
      buf(5:13) = reshape(pk%rot(:, :, i), [9])
      buf(14) = pk%scale(i)
      buf(15) = real(pk%kind_of(i), wp)
      buf(16) = real(pk%sieve(i), wp)
   end subroutine pack_particle

   !> A particle from `particle_doubles` doubles (pack_particle).
   pure subroutine unpack_particle(buf, g, x, rr, sc, kn, sv)
      real(wp), intent(in) :: buf(particle_doubles)
      integer, intent(out) :: g, kn, sv
      real(wp), intent(out) :: x(3), rr(3, 3), sc
      g = nint(buf(1))
      x = buf(2:4)
      rr = reshape(buf(5:13), [3, 3])
      sc = buf(14)
      kn = nint(buf(15))
      sv = nint(buf(16))
   end subroutine unpack_particle

   !> Displacements (0-based) of consecutive parts of the given sizes.
   pure subroutine displacements(counts, displ)
      integer, intent(in) :: counts(0:)
      integer, intent(out) :: displ(0:)
      integer :: r
      displ(0) = 0
      do r = 1, size(counts) - 1
         displ(r) = displ(r - 1) + counts(r - 1)
      end do
   end subroutine displacements

   !> The kinds built in shares by the processes of the communicator (anm_mpi_kinds).
   subroutine kinds_exchange(self, kx)
      !> Distributor.
      class(mpi_distributor_type), intent(in) :: self
      !> Exchange.
      class(kind_exchange_type), allocatable, intent(out) :: kx
      type(mpi_kinds_type) :: m
      call new_mpi_kinds(m, self%comm)
      allocate (kx, source=m)
   end subroutine kinds_exchange

   !> Record, at the end of a sieve, the particles in this process' cell list (its slab and halo),
   !> in the packing and in this process' arrays (counting only).
   subroutine note_slab(self, sieve, nlocal, np, held)
      !> Distributor.
      class(mpi_distributor_type), intent(in) :: self
      !> Sieve that ended.
      integer, intent(in) :: sieve
      !> Particles in this process' cell list, and in the packing (over all processes).
      integer, intent(in) :: nlocal, np
      !> Divided arrays: particles in this process' arrays (0: not divided).
      integer, intent(in) :: held
      if (.not. associated(self%stats)) return
      if (sieve < 1 .or. sieve > size(self%stats%slab_local)) return
      self%stats%slab_local(sieve) = nlocal
      self%stats%slab_total(sieve) = np
      self%stats%held(sieve) = held
   end subroutine note_slab

   !> Count one batch of n members of `bytes` each (nothing is communicated on one process).
   subroutine record_batch(st, sieve, n, bytes, nranks)
      type(comm_stats_type), intent(inout) :: st
      integer, intent(in) :: sieve, n, bytes, nranks
      integer, allocatable :: i1(:), i2(:)
      integer(int64), allocatable :: i3(:)
      if (st%nbatch == size(st%sieve)) then
         allocate (i1(2 * st%nbatch), i2(2 * st%nbatch), i3(2 * st%nbatch))
         i1(:st%nbatch) = st%sieve
         i2(:st%nbatch) = st%members
         i3(:st%nbatch) = st%bytes
         call move_alloc(i1, st%sieve)
         call move_alloc(i2, st%members)
         call move_alloc(i3, st%bytes)
      end if
      st%nbatch = st%nbatch + 1
      st%sieve(st%nbatch) = sieve
      st%members(st%nbatch) = n
      st%bytes(st%nbatch) = 0
      if (nranks > 1) st%bytes(st%nbatch) = int(n, int64) * bytes
      st%attempt_bytes = bytes
   end subroutine record_batch

   !> Print the counters per sieve and in all, and the peak memory (VmHWM) over the processes
   !> (collective; rank 0 prints to `unit`): lines starting "mpi:".
   subroutine write_comm_stats(dist, unit)
      !> Distributor (counting).
      type(mpi_distributor_type), intent(in) :: dist
      !> Output unit (rank 0).
      integer, intent(in) :: unit
      integer(int64) :: mem, lo, hi, sum_mem, total
      integer :: s, nb, nsieve, per
      integer(int64), allocatable :: b(:)
      integer, allocatable :: nm(:)
      real :: cpu
      integer :: slab_lo(64), slab_hi(64), held_lo(64), held_hi(64)
      integer(int64) :: xbytes, bbytes
      character(len=*), parameter :: fmt_sieve = '("mpi: sieve ",i0,": ",i0," batches, ",i0,' // &
                                     '" members, ",i0," bytes gathered to each rank (per batch min/median/max ",' // &
                                     'i0,"/",i0,"/",i0,")")'
      character(len=*), parameter :: fmt_window = '("mpi: sieve ",i0,": ",i0," batches, ",i0,' // &
                                      '" members, ",i0," bytes reduced by each rank (per batch min/median/max ",' // &
                                      'i0,"/",i0,"/",i0,")")'
      mem = peak_memory_kb()
      if (associated(dist%stats)) then
         call MPI_Allreduce(dist%stats%slab_local, slab_lo, size(slab_lo), MPI_INTEGER, MPI_MIN, dist%comm)
         call MPI_Allreduce(dist%stats%slab_local, slab_hi, size(slab_hi), MPI_INTEGER, MPI_MAX, dist%comm)
         call MPI_Allreduce(dist%stats%held, held_lo, size(held_lo), MPI_INTEGER, MPI_MIN, dist%comm)
         call MPI_Allreduce(dist%stats%held, held_hi, size(held_hi), MPI_INTEGER, MPI_MAX, dist%comm)
         call MPI_Allreduce(dist%stats%exchange_bytes, xbytes, 1, MPI_INTEGER8, MPI_MAX, dist%comm)
         call MPI_Allreduce(dist%stats%block_bytes, bbytes, 1, MPI_INTEGER8, MPI_MAX, dist%comm)
      end if
      call MPI_Allreduce(mem, lo, 1, MPI_INTEGER8, MPI_MIN, dist%comm)
      call MPI_Allreduce(mem, hi, 1, MPI_INTEGER8, MPI_MAX, dist%comm)
      call MPI_Allreduce(mem, sum_mem, 1, MPI_INTEGER8, MPI_SUM, dist%comm)
      if (dist%rank /= 0 .or. .not. associated(dist%stats)) return
      associate (st => dist%stats)
         nsieve = 0
         if (st%nbatch > 0) nsieve = maxval(st%sieve(:st%nbatch))
         total = 0
         do s = 1, nsieve
            nb = count(st%sieve(:st%nbatch) == s)
            if (nb == 0) cycle
            b = pack(st%bytes(:st%nbatch), st%sieve(:st%nbatch) == s)
            nm = pack(st%members(:st%nbatch), st%sieve(:st%nbatch) == s)
            per = 0
            if (dist%nranks > 1) per = st%attempt_bytes
            if (st%slabs) then
               write (unit, fmt_window) s, nb, sum(int(nm, int64)), sum(b), minval(b), 8 * median(int(b / 8)), maxval(b)
            else
               write (unit, fmt_sieve) s, nb, sum(int(nm, int64)), sum(b), minval(nm) * per, median(nm) * per, &
                  maxval(nm) * per
            end if
            total = total + sum(b)
         end do
         if (st%slabs) then
            write (unit, '("mpi: in all ",i0," batches (slabs), ",i0," first-fit reductions (MPI_Allreduce MIN, ",' // &
                   '"8 bytes per member searched), ",i0," bytes reduced by each rank; ",i0," MPI_Allreduce of 8 ",' // &
                   '"bytes (the batch clock, the run attributes); ",i0," ranks x ",i0," threads")') st%nbatch, &
               st%windows, st%window_bytes, st%reductions, dist%nranks, dist%workers / dist%nranks
         else
            write (unit, '("mpi: in all ",i0," batches, ",i0," bytes gathered to each rank (",i0," bytes per ",' // &
                   '"attempt, one MPI_Allgatherv per batch), ",i0," MPI_Allreduce of 8 bytes (the batch clock, ",' // &
                   '"the run attributes); ",i0," ranks x ",i0," threads")') st%nbatch, total, st%attempt_bytes, &
               st%reductions, dist%nranks, dist%workers / dist%nranks
         end if
         do s = 1, size(slab_lo)
            if (st%slab_total(s) == 0) cycle
            write (unit, '("mpi: sieve ",i0," end: each rank''s cell list holds ",i0," to ",i0," of the ",i0,' // &
                   '" particles (slab and halo; ",f0.3," to ",f0.3," of them, 1/ranks = ",f0.3,")")') s, slab_lo(s), &
               slab_hi(s), st%slab_total(s), real(slab_lo(s)) / st%slab_total(s), real(slab_hi(s)) / st%slab_total(s), &
               1.0 / dist%nranks
            if (held_hi(s) > 0) write (unit, '("mpi: sieve ",i0," end: each rank''s particle arrays hold ",i0,' // &
                                           '" to ",i0," of them (divided arrays)")') s, held_lo(s), held_hi(s)
         end do
         if (any(held_hi > 0)) write (unit, '("mpi: divided arrays: ",i0," exchanges of particles (slabs moved, ",' // &
                                          '"reach grown), at most ",i0," bytes received by a rank in them; at most ",' // &
                                          'i0," bytes received by a rank when the particles went to their blocks ",' // &
                                          '"of ids for the output (MPI_Alltoallv, 128 bytes per particle)")') &
            st%exchanges, xbytes, bbytes
         if (dist%spatial .and. st%slabs) then
            write (unit, '("mpi: load balance: busy time largest/mean ",f0.2," at the first check, ",f0.2,' // &
                   '" at the last; the slabs moved ",i0," times")') dist%bal%first_ratio, dist%bal%last_ratio, &
               dist%bal%moves
            if (allocated(dist%bal%bounds)) write (unit, '("mpi: slab bounds along x (mm) after the last move:",' // &
                                                   '*(1x,f0.3))') dist%bal%bounds
         end if
         if (st%sweep_batches > 0) write (unit, '("mpi: dense sweeps: ",i0," batches of trials evaluated in ",' // &
                                          '"shares, ",i0," trials, ",i0," bytes reduced by each rank (MPI_Allreduce ",' // &
                                          '"MIN, 8 bytes per trial), ",f0.2," s wall in those reductions; ",' // &
                                          '"rank 0 evaluated its share in ",f0.2," s CPU")') &
            st%sweep_batches, st%sweep_trials, st%sweep_bytes, st%sweep_wall, st%sweep_cpu
         call cpu_time(cpu)
         write (unit, '("mpi: rank 0: phase 1 ",f0.2," s CPU (",f0.2," s wall), waiting in the gathers ",f0.2,' // &
                '" s wall; the whole process ",f0.2," s CPU")') st%phase1_cpu, st%phase1_wall, st%gather_wall, cpu
         write (unit, '("mpi: peak memory per rank (VmHWM) min/mean/max ",f0.1,"/",f0.1,"/",f0.1," MB")') &
            real(lo, wp) / 1024, real(sum_mem, wp) / 1024 / dist%nranks, real(hi, wp) / 1024
      end associate
   end subroutine write_comm_stats

   !> Peak resident memory of this process (kB, VmHWM of /proc/self/status; 0 when unknown).
   function peak_memory_kb() result(kb)
      integer(int64) :: kb
      character(len=256) :: line
      integer :: u, st
      kb = 0
      open (newunit=u, file="/proc/self/status", action="read", status="old", iostat=st)
      if (st /= 0) return
      do
         read (u, '(a)', iostat=st) line
         if (st /= 0) exit
         if (line(1:6) == "VmHWM:") then
            read (line(7:), *, iostat=st) kb
            exit
         end if
      end do
      close (u)
   end function peak_memory_kb

   !> The median of non-negative values (counting; the values are batch sizes, at most a few
   !> thousand).
   pure integer function median(v) result(m)
      integer, intent(in) :: v(:)
      integer, allocatable :: c(:)
      integer :: k, seen
      allocate (c(0:maxval(v)))
      c = 0
      do k = 1, size(v)
         c(v(k)) = c(v(k)) + 1
      end do
      seen = 0
      do m = 0, ubound(c, 1)
         seen = seen + c(m)
         if (2 * seen >= size(v)) return
      end do
   end function median

   !> Members of a batch of n on rank r of nranks (round robin).
   pure integer function members(n, r, nranks) result(m)
      integer, intent(in) :: n, r, nranks
      m = 0
      if (n > r) m = (n - r - 1) / nranks + 1
   end function members
end module anm_mpi_distributor
