!> A packing: the parked particles (centre, rotation, scale, kind, sieve), their kinds and a cell
!> list over them, with what every placement strategy needs: add, remove and move a particle,
!> query the particles near a sphere, and test whether a candidate pose fits (no overlap with the
!> walls or any parked particle, as the shell mode says).
!>
!> Ids. Particles are 1..np. `remove(i)` moves the last particle to id i. The cell list stores
!> records (one per insertion): `remove` and `move` retire the particle's record (it is skipped
!> from then on) and `move` inserts a new one; `compact` rebuilds the cell list from the live
!> particles (call it when many records are retired; RSA never retires any).
!>
!> Marks. `mark()` is the number of records so far; `fits(..., since=m)` tests only particles
!> added or moved after mark m (the phase-2 re-check of a batch). A mark is invalid after `compact`.
!>
!> Slabs (the MPI build's spatial decomposition, `nslab` > 1). The particle arrays hold every
!> particle (they are the model), the cell list only those a candidate centred in this process'
!> slab (`owns`) can meet: a particle whose bounding sphere comes within `reach` (the largest
!> bounding radius of a candidate to come, `set_reach`) of the slab. `add` inserts every particle;
!> `localize` takes those out of reach out of the cell list again (after a batch: every process
!> then decides the batch's re-checks alike). `fits` answers for candidates centred in the slab
!> exactly as the whole packing would; for others it may miss overlaps.
!>
!> Divided arrays (`divided`, with slabs): the particle arrays too hold only the particles in
!> reach of the slab (its own, whose centres it owns, and its halo), sorted by their global ids
!> `gid` (the order the processes parked them in; `ntotal` of them so far). `localize` and
!> `compact` drop the others from the arrays as well; `held_reach` is the reach for which the
!> arrays are complete (every particle within it of the slab is held): a reach beyond it, or
!> slabs moved, need the particles that other processes own (`take_particles`, after the MPI
!> build's exchange). Without `divided` particle i is the i-th parked (gid = i).
!>
!> Usage:
!>     call new_packing(pk, params, kinds)          ! kinds moved in (pk%kinds)
!>     if (pk%fits(k, x, r, sc, scratch)) call pk%add(k, x, r, sc, sieve)
!>     call pk%move(i, x2, r2);  call pk%remove(i)
!>     call pk%neighbours(x, rho, ids, shifts, n)
module anm_parking_packing
   use anm_core_kinds, only: wp
   use anm_contact_body, only: contact_body_type
   use anm_contact_overlap, only: contact_params_type, bodies_overlap, first_stages, body_crosses_walls
   use anm_config_shells, only: shell_mode
   use anm_neighbours_cell_list, only: cell_list_type, new_cell_list
   use anm_parking_kinds, only: particle_kind_type, body_holder
   implicit none
   private

   public :: packing_type, packing_params_type, fit_scratch_type, new_packing, near_slab

   !> What a packing needs of the run (filled by the driver).
   type :: packing_params_type
      !> Box edges (mm).
      real(wp) :: box(3) = 1.0_wp
      !> Periodic boundaries (else walls).
      logical :: periodic = .true.
      !> Smallest bounding radius expected (mm; sizes the cell list).
      real(wp) :: rho_min = 1.0_wp
      !> Shell layers (0: none) and shell mode (`shell_mode`).
      integer :: nlayer = 0
      integer :: mode = shell_mode%exclude
      !> Contact test parameters.
      type(contact_params_type) :: contact
      !> Slabs along x (1: the whole box) and this process' slab (0-based).
      integer :: nslab = 1, slab = 0
      !> With slabs: the particle arrays hold only the slab's particles and halo (see the notes).
      logical :: divided = .false.
   end type packing_params_type

   !> Scratch of one thread for `fits` and `neighbours` (candidate ids and image shifts).
   type :: fit_scratch_type
      integer, allocatable :: cand(:)
      real(wp), allocatable :: shift(:, :)
   end type fit_scratch_type

   !> The parked particles.
   !> Records at the first reordering of the cell list's blocks (below, the pool fits in cache).
   integer, parameter :: first_reorder = 2**16

   type :: packing_type
      !> Parameters.
      type(packing_params_type) :: p
      !> Kinds (built by the caller before a particle of the kind is added).
      type(particle_kind_type), allocatable :: kinds(:)
      !> Number of particles (held by this process), and parked by all processes.
      integer :: np = 0, ntotal = 0
      !> Divided arrays: the global id of each particle held (ascending; unallocated otherwise).
      integer, allocatable :: gid(:)
      !> Divided arrays: the reach for which the particles held are complete (mm).
      real(wp) :: held_reach = huge(1.0_wp)
      !> Centre (3, :), rotation body to world (3, 3, :), scale, bounding radius (mm).
      real(wp), allocatable :: center(:, :), rot(:, :, :), scale(:), rho(:)
      !> Kind and sieve of each particle.
      integer, allocatable :: kind_of(:), sieve(:)
      !> Cell-list records: inserted so far, retired, record of each particle, particle of each
      !> record (0: retired).
      integer :: nrecord = 0, ndead = 0
      integer, allocatable :: record(:), owner(:)
      !> Record count at which the cell list's blocks are next laid out in cell order
      !> (`cell_list_type%reorder`; doubled each time).
      integer :: next_reorder = first_reorder
      type(cell_list_type) :: cl
      !> Slabs: the largest bounding radius of a candidate to come (mm), and this process' slab
      !> [slab_lo, slab_hi) along x (mm; the first slab also owns x < slab_lo, the last x >=
      !> slab_hi; equal slabs from `new_packing`, `set_slab` moves them).
      real(wp) :: reach = 0.0_wp, slab_lo = 0.0_wp, slab_hi = 0.0_wp
   contains
      !> Add a particle.
      procedure :: add
      !> Remove a particle (the last one takes its id).
      procedure :: remove
      !> Move a particle to a new pose.
      procedure :: move
      !> Rebuild the cell list from the live particles.
      procedure :: compact
      !> Room for a given number of particles (and cell-list records) without growing.
      procedure :: reserve
      !> Free the cell list (the packing then takes no more particles nor queries).
      procedure :: release
      !> Number of cell-list records so far (for `fits(..., since=)`).
      procedure :: mark
      !> Particles whose bounding spheres meet a sphere.
      procedure :: neighbours
      !> Whether a candidate pose overlaps nothing.
      procedure :: fits
      !> Whether a centre lies in this process' slab.
      procedure :: owns
      !> Whether particle i is within reach of this process' slab.
      procedure :: in_region
      !> Take the particles from `first` on that are out of reach out of the cell list.
      procedure :: localize
      !> Set the reach (the cell list is rebuilt when it grows).
      procedure :: set_reach
      !> Move this process' slab (the cell list is rebuilt).
      procedure :: set_slab
      !> This process' slab [lo, hi) along x.
      procedure :: slab_bounds
      !> Add particles parked by other processes to the arrays (divided arrays).
      procedure :: take_particles
   end type packing_type

   !> Initial capacity (particles).
   integer, parameter :: initial_capacity = 4096
   !> Capacity beyond which the particle arrays grow by half instead of doubling (the last growth
   !> then leaves at most a third of the arrays unused).
   integer, parameter :: gentle_growth = 2**20
   !> Longest candidate list that `fits` sorts by likely overlap (`likely_first`).
   integer, parameter :: max_sorted = 64

contains

   !> An empty packing; `kinds` is moved into it.
   subroutine new_packing(pk, params, kinds)
      !> Packing.
      type(packing_type), intent(out) :: pk
      !> Parameters.
      type(packing_params_type), intent(in) :: params
      !> Kinds (deallocated on return).
      type(particle_kind_type), allocatable, intent(inout) :: kinds(:)
      integer :: n
      pk%p = params
      call move_alloc(kinds, pk%kinds)
      n = initial_capacity
      call new_cell_list(pk%cl, params%box, params%periodic, params%rho_min, capacity=n)
      allocate (pk%center(3, n), pk%rot(3, 3, n), pk%scale(n), pk%rho(n), pk%sieve(n), pk%kind_of(n))
      allocate (pk%record(n), pk%owner(n))
      if (params%divided .and. params%nslab > 1) allocate (pk%gid(n))
      pk%slab_lo = params%box(1) * params%slab / max(1, params%nslab)
      pk%slab_hi = params%box(1) * (params%slab + 1) / max(1, params%nslab)
   end subroutine new_packing

   !> Add a particle of kind kn at centre x (inside the box), rotation rr, scale sc; its id is np.
   subroutine add(self, kn, x, rr, sc, sieve)
      !> Packing.
      class(packing_type), intent(inout) :: self
      !> Kind (built).
      integer, intent(in) :: kn
      !> Centre (mm), rotation (body to world), scale.
      real(wp), intent(in) :: x(3), rr(3, 3), sc
      !> Sieve.
      integer, intent(in) :: sieve
      integer :: np
      if (self%np == size(self%scale)) call grow(self)
      self%np = self%np + 1
      self%ntotal = self%ntotal + 1
      np = self%np
      if (allocated(self%gid)) self%gid(np) = self%ntotal
      self%center(:, np) = x
      self%rot(:, :, np) = rr
      self%scale(np) = sc
      self%rho(np) = sc * self%kinds(kn)%r_out
      self%sieve(np) = sieve
      self%kind_of(np) = kn
      call insert_record(self, np)
   end subroutine add

   !> Insert a new cell-list record for particle i.
   subroutine insert_record(self, i)
      type(packing_type), intent(inout) :: self
      integer, intent(in) :: i
      integer, allocatable :: o2(:)
      if (self%nrecord == size(self%owner)) then
         allocate (o2(merge(2 * self%nrecord, self%nrecord + self%nrecord / 2, self%nrecord < gentle_growth)))
         o2(:self%nrecord) = self%owner(:self%nrecord)
         call move_alloc(o2, self%owner)
      end if
      self%nrecord = self%nrecord + 1
      self%owner(self%nrecord) = i
      self%record(i) = self%nrecord
      call self%cl%insert(self%nrecord, self%center(:, i), self%rho(i), &
                          rin=self%scale(i) * self%kinds(self%kind_of(i))%r_in_parked)
      ! blocks in cell order now and then (amortised: at doublings of the record count)
      if (self%nrecord >= self%next_reorder) then
         call self%cl%reorder()
         self%next_reorder = merge(2 * self%next_reorder, huge(1), self%next_reorder < huge(1) / 2)
      end if
   end subroutine insert_record

   !> Remove particle i; the last particle takes id i (not for divided arrays, whose global ids
   !> must stay ascending: the dense strategy, which removes, never divides them).
   subroutine remove(self, i)
      !> Packing.
      class(packing_type), intent(inout) :: self
      !> Particle (1..np).
      integer, intent(in) :: i
      integer :: last
      last = self%np
      if (self%record(i) > 0) then
         self%owner(self%record(i)) = 0
         self%ndead = self%ndead + 1
      end if
      if (i /= last) then
         self%center(:, i) = self%center(:, last)
         self%rot(:, :, i) = self%rot(:, :, last)
         self%scale(i) = self%scale(last)
         self%rho(i) = self%rho(last)
         self%sieve(i) = self%sieve(last)
         self%kind_of(i) = self%kind_of(last)
         if (allocated(self%gid)) self%gid(i) = self%gid(last)
         self%record(i) = self%record(last)
         if (self%record(i) > 0) self%owner(self%record(i)) = i
      end if
      self%np = last - 1
      self%ntotal = self%ntotal - 1
   end subroutine remove

   !> Move particle i to centre x (inside the box) and rotation rr (and scale sc when given).
   subroutine move(self, i, x, rr, sc)
      !> Packing.
      class(packing_type), intent(inout) :: self
      !> Particle (1..np).
      integer, intent(in) :: i
      !> New centre (mm) and rotation.
      real(wp), intent(in) :: x(3), rr(3, 3)
      !> New scale.
      real(wp), intent(in), optional :: sc
      if (self%record(i) > 0) then
         self%owner(self%record(i)) = 0
         self%ndead = self%ndead + 1
      end if
      self%center(:, i) = x
      self%rot(:, :, i) = rr
      if (present(sc)) then
         self%scale(i) = sc
         self%rho(i) = sc * self%kinds(self%kind_of(i))%r_out
      end if
      call insert_record(self, i)
   end subroutine move

   !> Rebuild the cell list from the live particles (record i for particle i with one slab; with
   !> slabs, from the particles in reach; with divided arrays the others leave the arrays too;
   !> marks are reset).
   subroutine compact(self)
      !> Packing.
      class(packing_type), intent(inout) :: self
      integer :: i
      if (allocated(self%gid)) then
         ! the cell list is rebuilt below: the dropped particles need not leave it
         self%record(:self%np) = 0
         call drop_out_of_reach(self, 1)
      end if
      call new_cell_list(self%cl, self%p%box, self%p%periodic, self%p%rho_min, capacity=max(initial_capacity, self%np))
      self%nrecord = 0
      self%ndead = 0
      self%next_reorder = huge(1)
      do i = 1, self%np
         if (self%in_region(i)) then
            call insert_record(self, i)
         else
            self%record(i) = 0
         end if
      end do
      if (self%nrecord >= first_reorder) call self%cl%reorder()
      self%next_reorder = max(first_reorder, merge(2 * self%nrecord, huge(1), self%nrecord < huge(1) / 2))
   end subroutine compact

   !> Divided arrays: particles first..np out of reach of the slab leave the arrays (the others
   !> keep their order, and their records follow them); the arrays are then complete for the
   !> current reach at most.
   subroutine drop_out_of_reach(self, first)
      type(packing_type), intent(inout) :: self
      integer, intent(in) :: first
      integer :: i, n
      n = max(1, first) - 1
      do i = max(1, first), self%np
         if (.not. self%in_region(i)) then
            if (self%record(i) > 0) then
               call self%cl%remove(self%record(i), self%center(:, i), self%rho(i))
               self%owner(self%record(i)) = 0
            end if
            cycle
         end if
         n = n + 1
         if (n == i) cycle
         self%center(:, n) = self%center(:, i)
         self%rot(:, :, n) = self%rot(:, :, i)
         self%scale(n) = self%scale(i)
         self%rho(n) = self%rho(i)
         self%sieve(n) = self%sieve(i)
         self%kind_of(n) = self%kind_of(i)
         self%gid(n) = self%gid(i)
         self%record(n) = self%record(i)
         if (self%record(n) > 0) self%owner(self%record(n)) = n
      end do
      self%np = n
      self%held_reach = min(self%held_reach, self%reach)
   end subroutine drop_out_of_reach

   !> Make room for n particles and as many cell-list records and blocks (nothing changes when
   !> there is room already; else room for 1/32 more, so that a slowly rising estimate does not copy the
   !> arrays each time): a caller that knows about how many particles will come saves the
   !> copies and the unused part of the growth by doubling.
   subroutine reserve(self, n)
      !> Packing.
      class(packing_type), intent(inout) :: self
      !> Particles (and records) to hold.
      integer, intent(in) :: n
      integer, allocatable :: o2(:)
      integer :: m
      m = n + n / 32
      if (n > size(self%scale)) call resize(self, m)
      if (n > size(self%owner)) then
         allocate (o2(m))
         o2(:self%nrecord) = self%owner(:self%nrecord)
         call move_alloc(o2, self%owner)
      end if
      ! a block per record at most: the pool never grows (nor copies) before n records; unused
      ! blocks are never written, so they cost no memory
      if (n > size(self%cl%blocks)) call self%cl%reserve(m)
   end subroutine reserve

   !> Free the cell list: no more `add`, `move`, `compact`, `neighbours` nor `fits` (the particle
   !> arrays stay).
   subroutine release(self)
      !> Packing.
      class(packing_type), intent(inout) :: self
      type(cell_list_type) :: empty
      self%cl = empty
      if (allocated(self%owner)) deallocate (self%owner)
   end subroutine release

   !> Number of cell-list records so far.
   pure integer function mark(self) result(m)
      !> Packing.
      class(packing_type), intent(in) :: self
      m = self%nrecord
   end function mark

   !> The particles whose bounding spheres meet the sphere (x, rho): ids(1:n), with image shifts
   !> shifts(:, 1:n) (the image of particle ids(k) meeting the sphere has centre
   !> center(:, ids(k)) + shifts(:, k)).
   subroutine neighbours(self, x, rho, ids, shifts, n)
      !> Packing.
      class(packing_type), intent(in) :: self
      !> Centre (inside the box) and radius of the sphere (mm).
      real(wp), intent(in) :: x(3), rho
      !> Particle ids (grown as needed).
      integer, allocatable, intent(inout) :: ids(:)
      !> Image shifts (3, :) (grown as needed).
      real(wp), allocatable, intent(inout) :: shifts(:, :)
      !> Number of particles.
      integer, intent(out) :: n
      integer :: ncand, i, j
      logical :: hit
      call self%cl%neighbours(x, rho, ids, shifts, ncand, hit)
      n = 0
      do i = 1, ncand
         j = self%owner(ids(i))
         if (j == 0) cycle
         ! the cell list's radii are rounded up: the exact test
         if (sum((self%center(:, j) + shifts(:, i) - x)**2) >= (rho + self%rho(j))**2) cycle
         n = n + 1
         ids(n) = j
         shifts(:, n) = shifts(:, i)
      end do
   end subroutine neighbours

   !> This process' slab [lo, hi) along x (mm).
   pure subroutine slab_bounds(self, lo, hi)
      !> Packing.
      class(packing_type), intent(in) :: self
      !> Bounds (mm).
      real(wp), intent(out) :: lo, hi
      lo = self%slab_lo
      hi = self%slab_hi
   end subroutine slab_bounds

   !> Whether centre x lies in this process' slab [lo, hi) (the first slab also owns x < lo, the
   !> last x >= hi; the processes' bounds must tile the box edge alike). Always true with one slab.
   pure logical function owns(self, x)
      !> Packing.
      class(packing_type), intent(in) :: self
      !> Centre (mm).
      real(wp), intent(in) :: x(3)
      owns = .true.
      if (self%p%nslab <= 1) return
      owns = (x(1) >= self%slab_lo .or. self%p%slab == 0) .and. &
             (x(1) < self%slab_hi .or. self%p%slab == self%p%nslab - 1)
   end function owns

   !> Whether particle i can meet a candidate centred in this process' slab (`near_slab`). Always
   !> true with one slab.
   pure logical function in_region(self, i)
      !> Packing.
      class(packing_type), intent(in) :: self
      !> Particle.
      integer, intent(in) :: i
      in_region = .true.
      if (self%p%nslab <= 1) return
      in_region = near_slab(self%p, self%slab_lo, self%slab_hi, self%p%slab, self%reach, self%center(1, i), self%rho(i))
   end function in_region

   !> Move this process' slab to [lo, hi) along x (mm) and rebuild the cell list from the
   !> particles then in reach. Every process must move its slab in the same call, so that the
   !> slabs keep tiling the box edge (the MPI build's load balance). With divided arrays the
   !> arrays then miss the particles of the slab's new part: the MPI build moves the bounds
   !> itself and sends them (`take_particles`).
   subroutine set_slab(self, lo, hi)
      !> Packing.
      class(packing_type), intent(inout) :: self
      !> Bounds (mm), lo < hi.
      real(wp), intent(in) :: lo, hi
      self%slab_lo = lo
      self%slab_hi = hi
      if (self%p%nslab > 1) call self%compact()
   end subroutine set_slab

   !> Take particles first..np that are out of reach of this process' slab out of the cell list
   !> (and out of the arrays with divided arrays; nothing with one slab).
   subroutine localize(self, first)
      !> Packing.
      class(packing_type), intent(inout) :: self
      !> First particle to look at.
      integer, intent(in) :: first
      integer :: i
      if (self%p%nslab <= 1) return
      if (allocated(self%gid)) then
         call drop_out_of_reach(self, first)
         return
      end if
      do i = max(1, first), self%np
         if (self%record(i) == 0) cycle
         if (self%in_region(i)) cycle
         call self%cl%remove(self%record(i), self%center(:, i), self%rho(i))
         self%owner(self%record(i)) = 0
         self%record(i) = 0
      end do
   end subroutine localize

   !> Set the reach: the largest bounding radius (mm) of the candidates to come. When it grows
   !> (a sieve of larger particles, or a kind built later with a larger radius), the cell list is
   !> rebuilt from the particles now in reach; a smaller reach keeps the records it has. With
   !> divided arrays a reach beyond `held_reach` needs the other processes' particles first (the
   !> MPI build's `complete_region`).
   subroutine set_reach(self, r)
      !> Packing.
      class(packing_type), intent(inout) :: self
      !> Reach (mm).
      real(wp), intent(in) :: r
      logical :: grown
      grown = r > self%reach
      self%reach = r
      ! (divided arrays: also with none held, so that held_reach stays the same on every process)
      if (grown .and. self%p%nslab > 1 .and. (self%np > 0 .or. allocated(self%gid))) call self%compact()
   end subroutine set_reach

   !> No overlap of a particle of kind kn at pose (x, rr, sc) with the walls (non-periodic) or any
   !> parked particle, as the shell mode says. With `since` (> 0), only the particles added or
   !> moved after that mark are tested, and the walls are not. With `exclude` (a parked particle's
   !> id: the trial pose of a move), that particle itself is skipped (its periodic images are not).
   logical function fits(self, kn, x, rr, sc, scratch, since, exclude, hint, blocker) result(ok)
      !> Packing.
      class(packing_type), intent(in) :: self
      !> Kind (built).
      integer, intent(in) :: kn
      !> Centre (inside the box), rotation, scale.
      real(wp), intent(in) :: x(3), rr(3, 3), sc
      !> The calling thread's scratch.
      type(fit_scratch_type), intent(inout) :: scratch
      !> Mark (`mark()`) after which particles are tested (default 0: all).
      integer, intent(in), optional :: since
      !> Particle to skip (default: none).
      integer, intent(in), optional :: exclude
      !> Particle tested first when it is a candidate (a likely overlap, e.g. the one that refused
      !> the same particle's last trial); the answer does not depend on it.
      integer, intent(in), optional :: hint
      !> The particle an overlap was found with (0: none found by a pair test, e.g. a wall, a
      !> certain overlap in the cell list, or ok).
      integer, intent(out), optional :: blocker
      integer :: ncand, jmin, jskip, jhint, jb
      logical :: hit, sorted
      integer :: order(max_sorted)
      ok = .false.
      jb = 0
      if (present(blocker)) blocker = 0
      jhint = 0
      if (present(hint)) jhint = hint
      jmin = 0
      if (present(since)) jmin = since
      jskip = 0
      if (present(exclude)) jskip = exclude
      associate (p => self%p, kq => self%kinds(kn), bq => self%kinds(body_holder(self%kinds, kn))%body)
         if (.not. p%periodic .and. jmin == 0) then
            if (p%nlayer > 0 .and. p%mode == shell_mode%exclude) then
               if (body_crosses_walls(bq, x, rr, sc, p%box, margin=sc * kq%gap)) return
            else
               if (body_crosses_walls(bq, x, rr, sc, p%box)) return
            end if
         end if
         if (self%ndead == 0 .and. jskip == 0) then
            call self%cl%neighbours(x, sc * kq%r_out, scratch%cand, scratch%shift, ncand, hit, rin=sc * kq%r_in_query, &
                                    jmin=jmin)
            if (hit) return
         else
            ! a certain overlap may be a retired record or the excluded particle: no shortcut
            call self%cl%neighbours(x, sc * kq%r_out, scratch%cand, scratch%shift, ncand, hit, jmin=jmin)
         end if
         call live_candidates(self, scratch%cand, scratch%shift, ncand)
         call likely_first(self, kn, x, sc, scratch%cand, scratch%shift, ncand, jhint, order, sorted)
         ! an overlap the first stages prove, with any candidate, before any pair near contact is
         ! certified (the answer is the same: the full test would report that overlap too)
         if (ncand >= 2) then
            call scan_candidates(self, kq, bq, x, rr, sc, scratch, ncand, order, sorted, jskip, .true., .false., hit, jb)
            if (hit) then
               if (present(blocker)) blocker = jb
               return
            end if
         end if
         ! the full tests (without the proofs just run, when they were)
         call scan_candidates(self, kq, bq, x, rr, sc, scratch, ncand, order, sorted, jskip, .false., ncand >= 2, hit, jb)
         if (hit) then
            if (present(blocker)) blocker = jb
            return
         end if
      end associate
      ok = .true.
   end function fits

   !> Whether the candidate (kind kq at x, rr, sc) overlaps one of the ncand candidates in
   !> scratch (in the order of `likely_first`; jskip's own record and records set to 0 skipped),
   !> with the bodies and the gap the shell mode tests (`pair_gap`): by the full contact test, or
   !> (early) by its first stages alone (`first_stages`: an overlap only where the full test finds
   !> one). The early pass sets to 0 the records of the candidates whose first stages proved them apart,
   !> so that the full pass does not test them again. With proofs_done the full tests skip the
   !> early overlap proofs (the caller ran them on these pairs).
   pure subroutine scan_candidates(self, kq, bq, x, rr, sc, scratch, ncand, order, sorted, jskip, early, &
                                   proofs_done, hit, jhit)
      type(packing_type), intent(in) :: self
      type(particle_kind_type), intent(in) :: kq
      !> The candidate's bare body (its kind's shared one).
      type(contact_body_type), intent(in) :: bq
      real(wp), intent(in) :: x(3), rr(3, 3), sc
      type(fit_scratch_type), intent(inout) :: scratch
      integer, intent(in) :: ncand, order(:), jskip
      logical, intent(in) :: sorted, early, proofs_done
      logical, intent(out) :: hit
      !> The particle of the overlap found.
      integer, intent(out) :: jhit
      integer :: ii, i, j
      real(wp) :: xj(3), m
      logical :: apart, proved
      hit = .true.
      jhit = 0
      do ii = 1, ncand
         i = ii
         if (sorted) i = order(ii)
         j = scratch%cand(i)
         if (j == 0) cycle
         if (j == jskip) then
            if (all(scratch%shift(:, i) == 0.0_wp)) cycle
         end if
         xj = self%center(:, j) + scratch%shift(:, i)
         associate (rj => self%rot(:, :, j), sj => self%scale(j), &
                    bj => self%kinds(body_holder(self%kinds, self%kind_of(j)))%body)
            m = pair_gap(self%p, kq, sc, self%kinds(self%kind_of(j)), sj)
            jhit = j
            if (early) then
               call first_stages(bq, x, rr, sc, bj, xj, rj, sj, self%p%contact, proved, apart, margin=m)
               if (proved) return
               if (apart) scratch%cand(i) = 0
            else
               if (bodies_overlap(bq, x, rr, sc, bj, xj, rj, sj, self%p%contact, proofs_done=proofs_done, &
                                  margin=m)) return
            end if
         end associate
      end do
      hit = .false.
   end subroutine scan_candidates

   !> The gap (mm) the bare bodies of a candidate (kind kq, scale sc) and a parked particle (kind
   !> kj, scale sj) must keep: 0 without shells or with overlapping ones; with exclusion shells the
   !> sum of their thicknesses (both shells disjoint); with 'shell_overlap' the larger thickness
   !> (each shell misses the other bare body).
   pure real(wp) function pair_gap(p, kq, sc, kj, sj) result(m)
      type(packing_params_type), intent(in) :: p
      type(particle_kind_type), intent(in) :: kq, kj
      real(wp), intent(in) :: sc, sj
      if (p%nlayer == 0 .or. p%mode == shell_mode%overlap) then
         m = 0.0_wp
      else if (p%mode == shell_mode%exclude) then
         m = sc * kq%gap + sj * kj%gap
      else
         m = max(sc * kq%gap, sj * kj%gap)
      end if
   end function pair_gap

   !> Candidate records to particle ids, retired records dropped (order kept).
   pure subroutine live_candidates(self, cnd, shf, ncand)
      type(packing_type), intent(in) :: self
      integer, intent(inout) :: cnd(:)
      real(wp), intent(inout) :: shf(:, :)
      integer, intent(inout) :: ncand
      integer :: i, n, j
      n = 0
      do i = 1, ncand
         j = self%owner(cnd(i))
         if (j == 0) cycle
         n = n + 1
         cnd(n) = j
         shf(:, n) = shf(:, i)
      end do
      ncand = n
   end subroutine live_candidates

   !> The order in which to test the candidates: the most likely overlaps first, so that an
   !> attempt that fails usually fails at its first exact test. The key is where the centre
   !> distance lies between the certain-overlap and the bounding-sphere distances (0 to 1); the
   !> candidate that is particle jh (a hint, 0 for none) comes first.
   !> Short lists are sorted (insertion sort, stable: `sorted`, order(1:ncand)); long ones are kept
   !> in their order (`sorted` false, order not set).
   pure subroutine likely_first(self, kn, x, sc, cnd, shf, ncand, jh, order, sorted)
      type(packing_type), intent(in) :: self
      integer, intent(in) :: kn, ncand, jh
      real(wp), intent(in) :: x(3), sc
      integer, intent(in) :: cnd(:)
      real(wp), intent(in) :: shf(:, :)
      integer, intent(inout) :: order(max_sorted)
      logical, intent(out) :: sorted
      real(wp) :: key(max_sorted), kk, r_in, r_out
      integer :: i, m, j, oi
      sorted = ncand >= 2 .and. ncand <= max_sorted
      if (.not. sorted) return
      do i = 1, ncand
         order(i) = i
      end do
      do i = 1, ncand
         j = cnd(i)
         r_in = sc * self%kinds(kn)%r_in_query + self%scale(j) * self%kinds(self%kind_of(j))%r_in_parked
         r_out = sc * self%kinds(kn)%r_out + self%rho(j)
         key(i) = (norm2(self%center(:, j) + shf(:, i) - x) - r_in) / max(r_out - r_in, tiny(1.0_wp))
         if (j == jh) key(i) = -huge(1.0_wp)
      end do
      do i = 2, ncand
         oi = order(i)
         kk = key(oi)
         m = i - 1
         do while (m >= 1)
            if (key(order(m)) <= kk) exit
            order(m + 1) = order(m)
            m = m - 1
         end do
         order(m + 1) = oi
      end do
   end subroutine likely_first

   !> Whether a particle (centre x along x, bounding radius rho) can meet a candidate centred in
   !> slab `slab` [lo, hi) of the box (p%nslab slabs) whose bounding radius is at most `reach`:
   !> its centre lies within reach + rho of the slab along x (periodic: either way round; a
   !> relative margin of 1e-9 covers rounding).
   pure logical function near_slab(p, lo, hi, slab, reach, x, rho) result(near)
      !> Packing parameters (box, periodicity, slabs).
      type(packing_params_type), intent(in) :: p
      !> The slab's bounds (mm) and index (0-based; the end slabs own the centres beyond the
      !> box's faces too).
      real(wp), intent(in) :: lo, hi
      integer, intent(in) :: slab
      !> Reach (mm), the particle's centre along x and bounding radius (mm).
      real(wp), intent(in) :: reach, x, rho
      real(wp) :: a, b, d, lx
      near = .true.
      lx = p%box(1)
      a = lo
      b = hi
      if (slab == 0) a = min(a, 0.0_wp)
      if (slab == p%nslab - 1) b = max(b, lx)
      if (x >= a .and. x <= b) return
      if (p%periodic) then
         d = min(modulo(a - x, lx), modulo(x - b, lx))
      else
         d = max(a - x, x - b)
      end if
      near = d <= (reach + rho) * (1.0_wp + 1.0e-9_wp) + 1.0e-9_wp * lx
   end function near_slab

   !> Divided arrays: add particles parked earlier and held by other processes (global ids
   !> g(k), centres x(:, k), rotations rr(:, :, k), scales sc(k), kinds kn(k), sieves sv(k));
   !> those already held are skipped. The arrays stay sorted by global id and the cell list is
   !> rebuilt for the slab and reach as they now are (`compact`, which drops what is out of
   !> reach); the arrays are then complete for that reach (the caller received every particle
   !> within it of the slab).
   subroutine take_particles(self, g, x, rr, sc, kn, sv)
      !> Packing.
      class(packing_type), intent(inout) :: self
      !> Global ids (any order), centres, rotations, scales, kinds and sieves.
      integer, intent(in) :: g(:), kn(:), sv(:)
      real(wp), intent(in) :: x(:, :), rr(:, :, :), sc(:)
      integer, allocatable :: order(:), src(:)
      real(wp), allocatable :: c2(:, :), r2(:, :, :), s2(:)
      integer, allocatable :: k2(:), v2(:), g2(:)
      integer :: m, i, j, n, k, cap
      m = size(g)
      order = sort_index(g)
      ! merge the held arrays (ascending) with the received ones (ascending by `order`), each
      ! global id once; src > 0: held particle, < 0: received one
      allocate (src(self%np + m))
      i = 1
      j = 1
      n = 0
      do while (i <= self%np .or. j <= m)
         if (j > m) then
            k = i
            i = i + 1
         else if (i > self%np) then
            k = -order(j)
            j = j + 1
         else if (self%gid(i) <= g(order(j))) then
            if (self%gid(i) == g(order(j))) j = j + 1
            k = i
            i = i + 1
         else
            k = -order(j)
            j = j + 1
         end if
         if (k < 0 .and. n > 0) then
            ! a particle received twice (the MPI exchange sends each once: only its owner sends it)
            if (gid_of(src(n)) == g(-k)) cycle
         end if
         n = n + 1
         src(n) = k
      end do
      ! one array at a time (the copy costs the largest array, not all of them)
      cap = max(size(self%scale), n + n / 32)
      allocate (c2(3, cap))
      do i = 1, n
         if (src(i) > 0) c2(:, i) = self%center(:, src(i))
         if (src(i) < 0) c2(:, i) = x(:, -src(i))
      end do
      call move_alloc(c2, self%center)
      allocate (r2(3, 3, cap))
      do i = 1, n
         if (src(i) > 0) r2(:, :, i) = self%rot(:, :, src(i))
         if (src(i) < 0) r2(:, :, i) = rr(:, :, -src(i))
      end do
      call move_alloc(r2, self%rot)
      allocate (s2(cap))
      do i = 1, n
         if (src(i) > 0) s2(i) = self%scale(src(i))
         if (src(i) < 0) s2(i) = sc(-src(i))
      end do
      call move_alloc(s2, self%scale)
      allocate (k2(cap))
      do i = 1, n
         if (src(i) > 0) k2(i) = self%kind_of(src(i))
         if (src(i) < 0) k2(i) = kn(-src(i))
      end do
      call move_alloc(k2, self%kind_of)
      allocate (v2(cap))
      do i = 1, n
         if (src(i) > 0) v2(i) = self%sieve(src(i))
         if (src(i) < 0) v2(i) = sv(-src(i))
      end do
      call move_alloc(v2, self%sieve)
      allocate (g2(cap))
      do i = 1, n
         g2(i) = gid_of(src(i))
      end do
      call move_alloc(g2, self%gid)
      deallocate (self%rho, self%record)
      allocate (self%rho(cap), self%record(cap))
      do i = 1, n
         self%rho(i) = self%scale(i) * self%kinds(self%kind_of(i))%r_out
      end do
      self%record = 0
      self%np = n
      if (size(self%owner) < cap) then
         deallocate (self%owner)
         allocate (self%owner(cap))
      end if
      call self%compact()
      self%held_reach = self%reach
   contains
      pure integer function gid_of(kk)
         integer, intent(in) :: kk
         if (kk > 0) then
            gid_of = self%gid(kk)
         else
            gid_of = g(-kk)
         end if
      end function gid_of
   end subroutine take_particles

   !> The permutation that sorts v ascending (merge sort; stable).
   pure function sort_index(v) result(idx)
      integer, intent(in) :: v(:)
      integer, allocatable :: idx(:)
      integer, allocatable :: tmp(:)
      integer :: n, w, lo, mid, hi, i, j, k
      n = size(v)
      allocate (idx(n), tmp(n))
      do i = 1, n
         idx(i) = i
      end do
      w = 1
      do while (w < n)
         lo = 1
         do while (lo <= n)
            mid = min(lo + w - 1, n)
            hi = min(lo + 2 * w - 1, n)
            i = lo
            j = mid + 1
            k = lo
            do while (i <= mid .and. j <= hi)
               if (v(idx(j)) < v(idx(i))) then
                  tmp(k) = idx(j)
                  j = j + 1
               else
                  tmp(k) = idx(i)
                  i = i + 1
               end if
               k = k + 1
            end do
            tmp(k:k + mid - i) = idx(i:mid)
            k = k + mid - i + 1
            tmp(k:k + hi - j) = idx(j:hi)
            idx(lo:hi) = tmp(lo:hi)
            lo = lo + 2 * w
         end do
         w = 2 * w
      end do
   end function sort_index

   !> Grow the particle arrays (double them; by half beyond gentle_growth).
   subroutine grow(self)
      type(packing_type), intent(inout) :: self
      integer :: n
      n = size(self%scale)
      call resize(self, merge(2 * n, n + n / 2, n < gentle_growth))
   end subroutine grow

   !> Particle arrays of capacity n (>= np), one array at a time (the copy costs the largest
   !> array, not all of them).
   subroutine resize(self, n)
      type(packing_type), intent(inout) :: self
      integer, intent(in) :: n
      real(wp), allocatable :: c2(:, :), r2(:, :, :), s2(:), h2(:)
      integer, allocatable :: i2(:), k2(:), g2(:)
      integer :: np
      np = self%np
      allocate (c2(3, n))
      c2(:, :np) = self%center(:, :np)
      call move_alloc(c2, self%center)
      allocate (r2(3, 3, n))
      r2(:, :, :np) = self%rot(:, :, :np)
      call move_alloc(r2, self%rot)
      allocate (s2(n))
      s2(:np) = self%scale(:np)
      call move_alloc(s2, self%scale)
      allocate (h2(n))
      h2(:np) = self%rho(:np)
      call move_alloc(h2, self%rho)
      allocate (i2(n))
      i2(:np) = self%sieve(:np)
      call move_alloc(i2, self%sieve)
      allocate (k2(n))
      k2(:np) = self%kind_of(:np)
      call move_alloc(k2, self%kind_of)
      allocate (g2(n))
      g2(:np) = self%record(:np)
      call move_alloc(g2, self%record)
      if (allocated(self%gid)) then
         allocate (g2(n))
         g2(:np) = self%gid(:np)
         call move_alloc(g2, self%gid)
      end if
   end subroutine resize
end module anm_parking_packing
