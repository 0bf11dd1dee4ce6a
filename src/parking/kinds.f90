!> Particle kinds: the precomputed data of one (sieve, shape[, width level]) combination (geometry
!> at the sieve's order, contact body, shell layers) and the set of them for a run, built lazily
!> (a kind is built when first needed; a kind equal to an earlier one is built once and copied;
!> the geometry and bare contact body of a (shape, order) are built once and copied to its width
!> levels, which differ only in their shells). Shells that take part in the packing ('exclude',
!> 'shell_overlap') have no contact body of their own: the packing keeps their thickness as a gap
!> around the bare bodies (`gap`). With p%cache_directory (ANM_CACHE) the bases and
!> shells are read from and written to an on-disk cache (anm_parking_kind_cache, docs/shells.md).
!> With an `exchange` (the MPI build), the processes build the kinds of a list in shares and send
!> each other what they built, in the cache's payload format.
!>
!> The kinds of sieve s are `first(s) .. first(s) + count(s) - 1`: `nlev` blocks (width levels,
!> shells in mm) of the sieve's shapes.
!>
!> Usage:
!>     call new_kind_set(ks, kinds, params, shapes, names, first_shape, nshape, order)
!>     call ks%build(kinds, [(k, k = ks%first(s), ks%first(s) + ks%count(s) - 1)], error)
module anm_parking_kinds
   use, intrinsic :: iso_fortran_env, only: int8, int64
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type, fatal_error
   use anm_core_filesystem, only: string_type
   use anm_sh_expansion, only: sh_expansion_type, sh_truncate
   use anm_geometry_properties, only: shape_geometry_type, compute_geometry
   use anm_contact_body, only: contact_body_type, new_contact_body, add_support_table, radial_bound
   use anm_shells_build, only: shell_report_type, build_layers
   use anm_config_shells, only: shell_mode
   use anm_shells_thickness, only: thickness_unit, thickness_to_shape_units
   use anm_parking_kind_cache, only: kind_cache_type, new_kind_cache, byte_writer_type, byte_reader_type, key_start, &
      & put_body, get_body, put_expansion, get_expansion
   implicit none
   private

   public :: particle_kind_type, kind_params_type, kind_set_type, new_kind_set, width_levels, cache_environment, kind_bytes, &
      & body_bytes, kind_exchange_type, body_holder

   !> Discrete widths per sieve when shell thickness is given in mm.
   integer, parameter :: width_levels = 8
   !> Attempts (placements tried, anywhere in the run) per contact body without a support table
   !> after which the built kinds' bodies get their tables (`add_tables`): a table costs about
   !> 15-20 ms at order 14-28 and saves a few microseconds per contact test near the body, so it
   !> pays for itself after some thousands of attempts. A job with few particles of many kinds
   !> (shells in mm) never builds them.
   integer, parameter :: attempts_per_table = 5000

   !> Precomputed data of one (sieve, shape[, width level]) combination.
   type :: particle_kind_type
      !> Index into the model's shapes.
      integer :: shape = 0
      !> Sieve.
      integer :: sieve = 0
      !> Order used.
      integer :: order = 0
      !> Width level (0: continuous widths).
      integer :: level = 0
      !> Geometry at the order used (shape units).
      real(wp) :: width = 0.0_wp, length = 0.0_wp, volume = 0.0_wp
      !> Bare particle (the only contact body: shells are tested as a gap around it), held by
      !> the kind `body_kind` only: the first kind built of a (shape, order); the others (width
      !> levels, sieves of the same source) share it and leave theirs empty.
      type(contact_body_type) :: body
      !> The kind whose `body` is this kind's bare body (0: the kind itself):
      !> `kinds(body_holder(kinds, k))%body`.
      integer :: body_kind = 0
      !> Thickness of the outermost shell (shape units) that the packing keeps as a gap around
      !> the bare body (modes 'exclude' and 'shell_overlap'; 0 otherwise): the distance test of
      !> `bodies_overlap` with a margin.
      real(wp) :: gap = 0.0_wp
      !> Outer surfaces of the layers (shape units) and the volume inside each: built only when
      !> asked for (`build_layers`: the kinds that hold particles, at the end of the parking).
      type(sh_expansion_type), allocatable :: layers(:)
      !> Volume inside each layer's outer surface (shape units).
      real(wp), allocatable :: layer_volume(:)
      !> Bounding radius of the largest body the overlap tests use (shape units).
      real(wp) :: r_out = 0.0_wp
      !> Radii (shape units) such that a particle of this kind, placed as a candidate, certainly
      !> overlaps a parked one whose centre is closer than scale r_in_query + scale_j r_in_parked
      !> (the inscribed radii of the bodies the shell mode tests: the overlap test's own first
      !> stage).
      real(wp) :: r_in_query = 0.0_wp, r_in_parked = 0.0_wp
   end type particle_kind_type

   !> What building a kind needs of the run's configuration (filled by the driver).
   type :: kind_params_type
      !> Namelist file (for messages).
      character(len=:), allocatable :: file
      !> Shell layers (0: none), their thicknesses and whether those are in mm (else fractions
      !> of the particle length).
      integer :: nlayer = 0
      real(wp), allocatable :: thickness(:)
      integer :: unit = thickness_unit%fraction_of_length
      !> Shell mode (`shell_mode`).
      integer :: mode = shell_mode%exclude
      !> Extended-grid size of the contact bodies.
      integer :: n_ext = 40
      !> Width range of each sieve (mm).
      real(wp), allocatable :: min_width(:), max_width(:)
      !> Folder of the on-disk cache of built kinds ('' or 'off': none; anm_parking_kind_cache).
      character(len=:), allocatable :: cache_directory
   end type kind_params_type

   !> Kinds built by several processes (the MPI build's anm_mpi_kinds): process `rank` of `nranks`
   !> builds items rank + 1, rank + 1 + nranks, ... of each list of kinds to build, and sends each
   !> (its payload) to the others with `broadcast`, one item at a time (so that at most one
   !> item's bytes are held beside the kinds).
   type, abstract :: kind_exchange_type
      !> Processes and this process (0-based).
      integer :: nranks = 1, rank = 0
      !> Kinds built here and received from the others (counters).
      integer :: built = 0, received = 0
   contains
      !> Process root's bytes to every process (collective).
      procedure(broadcast_bytes), deferred :: broadcast
   end type kind_exchange_type

   abstract interface
      subroutine broadcast_bytes(self, root, b)
         import :: kind_exchange_type, int8
         !> Exchange.
         class(kind_exchange_type), intent(in) :: self
         !> Sending process.
         integer, intent(in) :: root
         !> The bytes: given on root, received (allocated) on the others.
         integer(int8), allocatable, intent(inout) :: b(:)
      end subroutine broadcast_bytes
   end interface

   !> Bookkeeping of the kinds of a run.
   type :: kind_set_type
      !> Parameters.
      type(kind_params_type) :: p
      !> Width levels per sieve (1, or width_levels with shells in mm).
      integer :: nlev = 1
      !> First kind and number of kinds of each sieve.
      integer, allocatable :: first(:), count(:)
      !> The kind each kind is a copy of (itself when it is built on its own).
      integer, allocatable :: same(:)
      !> The kind of the same (shape, order) whose geometry and bare body a kind copied (set when built).
      integer, allocatable :: base(:)
      !> Kinds built so far; kinds whose geometry and bare body are built (`base`s).
      logical, allocatable :: built(:), base_built(:)
      !> Kinds whose shell layers are built (`build_layers`).
      logical, allocatable :: layered(:)
      !> The run's shapes and names (the model's).
      type(sh_expansion_type), allocatable :: shapes(:)
      type(string_type), allocatable :: names(:)
      !> On-disk cache of built bases and shells (off unless p%cache_directory names a folder).
      type(kind_cache_type) :: cache
      !> Bases (geometry and bare body) and shells built here (not read from the cache).
      integer :: bases_built = 0, shells_built = 0
      !> Processes sharing the building (the MPI build; unallocated: this process builds all).
      class(kind_exchange_type), allocatable :: exchange
      !> The run's attempts when support tables were last built (`add_tables`).
      integer(int64) :: attempts_tabled = 0
      !> Contact bodies given their support table here.
      integer :: tables_built = 0
   contains
      !> Build the kinds of a list that are not built yet.
      procedure :: build
      !> Build the shell layers of a list of kinds.
      procedure :: build_layers => build_kind_layers
      !> Support tables for the built kinds' contact bodies when the run's use pays for them.
      procedure :: add_tables
   end type kind_set_type

contains

   !> Describe every kind of a run (nothing is built yet): sieve s uses the shapes
   !> first_shape(s) + 1 .. first_shape(s) + nshape(s) at order min(order(s), nmax) (order < 0:
   !> the shape's own order).
   subroutine new_kind_set(ks, kinds, params, shapes, names, first_shape, nshape, order)
      !> Bookkeeping.
      type(kind_set_type), intent(out) :: ks
      !> Kinds (described, not built).
      type(particle_kind_type), allocatable, intent(out) :: kinds(:)
      !> Parameters.
      type(kind_params_type), intent(in) :: params
      !> The run's shapes and their names.
      type(sh_expansion_type), intent(in) :: shapes(:)
      character(len=*), intent(in) :: names(:)
      !> Per sieve: shapes before its first one, number of its shapes, order (< 0: full).
      integer, intent(in) :: first_shape(:), nshape(:), order(:)
      integer :: nsieve, s, n, lev, k, i, j
      ks%p = params
      if (allocated(params%cache_directory)) call new_kind_cache(ks%cache, params%cache_directory)
      ks%shapes = shapes
      allocate (ks%names(size(names)))
      do i = 1, size(names)
         ks%names(i)%s = trim(names(i))
      end do
      nsieve = size(first_shape)
      ks%nlev = 1
      if (params%nlayer > 0 .and. params%unit == thickness_unit%mm) ks%nlev = width_levels
      allocate (ks%first(nsieve), ks%count(nsieve))
      n = 0
      do s = 1, nsieve
         ks%first(s) = n + 1
         ks%count(s) = nshape(s) * ks%nlev
         n = n + ks%count(s)
      end do
      allocate (kinds(n))
      do s = 1, nsieve
         do lev = 1, ks%nlev
            do k = 1, nshape(s)
               i = ks%first(s) + (lev - 1) * nshape(s) + k - 1
               kinds(i)%shape = first_shape(s) + k
               kinds(i)%sieve = s
               kinds(i)%level = merge(lev, 0, ks%nlev > 1)
               kinds(i)%order = shapes(kinds(i)%shape)%nmax
               if (order(s) >= 0) kinds(i)%order = min(order(s), kinds(i)%order)
            end do
         end do
      end do
      ! a kind equal to an earlier one (same shape and order, and with shells in mm the same width:
      ! e.g. two sieves of one source) is built once and copied (build)
      allocate (ks%same(n), ks%built(n), ks%base(n), ks%base_built(n), ks%layered(n))
      ks%built = .false.
      ks%layered = .false.
      ks%base_built = .false.
      ks%base = [(i, i=1, n)]
      do i = 1, n
         ks%same(i) = i
         do j = 1, i - 1
            if (ks%same(j) /= j) cycle
            if (kinds(j)%shape /= kinds(i)%shape .or. kinds(j)%order /= kinds(i)%order) cycle
            if (ks%nlev > 1) then
               if (level_width(params, kinds(j)) /= level_width(params, kinds(i))) cycle
            end if
            ks%same(i) = j
            exit
         end do
      end do
   end subroutine new_kind_set

   !> Build the kinds `list` that are not built yet: the geometry and bare bodies of their bases
   !> (`base`, one per (shape, order), shared: `body_holder`) in parallel, the gap of their shells,
   !> then the copies (`same`). The shell layers come later (`build_layers`). A failure is
   !> returned.
   subroutine build(self, kinds, list, error)
      !> Bookkeeping.
      class(kind_set_type), intent(inout) :: self
      !> Kinds.
      type(particle_kind_type), intent(inout) :: kinds(:)
      !> Kinds wanted.
      integer, intent(in) :: list(:)
      !> Error of the first kind that failed.
      type(error_type), allocatable, intent(out) :: error
      logical, allocatable :: want(:)
      integer, allocatable :: todo(:)
      integer :: i, j, k, sieve, level
      allocate (want(size(kinds)))
      want = .false.
      do i = 1, size(list)
         if (.not. self%built(list(i))) want(self%same(list(i))) = .true.
      end do
      want = want .and. .not. self%built
      todo = pack([(k, k=1, size(kinds))], want)
      if (size(todo) > 0) then
         ! the bases first: geometry and bare body, once per (shape, order): a kind of the same
         ! (shape, order) built earlier, else the first such kind of this list
         do i = 1, size(todo)
            k = todo(i)
            if (self%base_built(k)) then
               self%base(k) = k
               cycle
            end if
            self%base(k) = k
            do j = 1, size(kinds)
               if (kinds(j)%shape /= kinds(k)%shape .or. kinds(j)%order /= kinds(k)%order) cycle
               if (self%base_built(j) .or. (j < k .and. want(j))) then
                  if (self%base_built(j) .or. self%base(j) == j) then
                     self%base(k) = j
                     exit
                  end if
               end if
            end do
         end do
         block
            integer, allocatable :: bases(:)
            integer :: nbuilt
            bases = pack(todo, self%base(todo) == todo .and. .not. self%base_built(todo))
            do i = 1, size(bases)
               kinds(bases(i))%body_kind = bases(i)
            end do
            if (size(bases) > 0) then
               call build_cached(self, kinds, bases, .true., nbuilt, error)
               if (allocated(error)) return
               self%bases_built = self%bases_built + nbuilt
               self%base_built(bases) = .true.
            end if
         end block
         do i = 1, size(todo)
            k = todo(i)
            if (self%base(k) /= k) then
               j = body_holder(kinds, self%base(k))
               call copy_base(kinds(self%base(k)), kinds(k), j, kinds(j)%body)
               self%base_built(k) = .true.
            end if
         end do
         ! shells: the gap the packing keeps (cheap); their layers when asked for (build_layers)
         if (self%p%nlayer > 0) then
            do i = 1, size(todo)
               k = todo(i)
               j = body_holder(kinds, k)
               call shell_radii(self%p, kinds(k), kinds(j)%body)
            end do
         end if
         self%built(todo) = .true.
      end if
      do i = 1, size(list)
         k = list(i)
         if (self%built(k)) cycle
         sieve = kinds(k)%sieve
         level = kinds(k)%level
         call copy_kind(kinds(self%same(k)), kinds(k), body_holder(kinds, self%same(k)))
         kinds(k)%sieve = sieve
         kinds(k)%level = level
         self%built(k) = .true.
      end do
   end subroutine build

   !> Build the shell layers of the kinds `list` (built first where they are not) that have none
   !> yet: from the cache where it has them, the others in parallel (shared between processes
   !> with an exchange) and stored; a kind equal to an earlier one (`same`) gets a copy. Called
   !> collectively with the same list on every process. Nothing without shells.
   subroutine build_kind_layers(self, kinds, list, error)
      !> Bookkeeping.
      class(kind_set_type), intent(inout) :: self
      !> Kinds.
      type(particle_kind_type), intent(inout) :: kinds(:)
      !> Kinds wanted.
      integer, intent(in) :: list(:)
      !> Error of the first kind that failed.
      type(error_type), allocatable, intent(out) :: error
      logical, allocatable :: want(:)
      integer, allocatable :: todo(:)
      integer :: i, k, o, nbuilt
      if (self%p%nlayer == 0) return
      call self%build(kinds, list, error)
      if (allocated(error)) return
      allocate (want(size(kinds)))
      want = .false.
      do i = 1, size(list)
         want(self%same(list(i))) = .true.
      end do
      want = want .and. .not. self%layered
      todo = pack([(k, k=1, size(kinds))], want)
      if (size(todo) > 0) then
         call build_cached(self, kinds, todo, .false., nbuilt, error)
         if (allocated(error)) return
         self%shells_built = self%shells_built + nbuilt
         self%layered(todo) = .true.
      end if
      do i = 1, size(list)
         k = list(i)
         if (self%layered(k)) cycle
         o = self%same(k)
         kinds(k)%layers = kinds(o)%layers
         kinds(k)%layer_volume = kinds(o)%layer_volume
         self%layered(k) = .true.
      end do
   end subroutine build_kind_layers

   !> The bases (`bases`: geometry and bare body) or the shell layers of kinds(list): from the
   !> cache where it has them, the others built in parallel (shared between processes with an
   !> exchange) and stored; nbuilt of them were built here.
   subroutine build_cached(self, kinds, list, bases, nbuilt, error)
      type(kind_set_type), intent(inout) :: self
      type(particle_kind_type), intent(inout) :: kinds(:)
      integer, intent(in) :: list(:)
      logical, intent(in) :: bases
      integer, intent(out) :: nbuilt
      type(error_type), allocatable, intent(out) :: error
      logical, allocatable :: hit(:)
      integer, allocatable :: fresh(:)
      integer :: i
      nbuilt = 0
      allocate (hit(size(list)))
      hit = .false.
      if (self%cache%on) then
         do i = 1, size(list)
            if (bases) then
               call load_base(self, kinds(list(i)), hit(i))
            else
               call load_shells(self, kinds(list(i)), hit(i))
            end if
         end do
      end if
      fresh = pack(list, .not. hit)
      call build_shared(self, kinds, fresh, bases, error)
      if (allocated(error)) return
      nbuilt = size(fresh)
      if (.not. self%cache%on) return
      do i = 1, size(fresh)
         if (bases) then
            call store_base(self, kinds(fresh(i)))
         else
            call store_shells(self, kinds(fresh(i)))
         end if
      end do
   end subroutine build_cached

   !> Index of the kind whose `body` is kind k's bare body (`body_kind`; k itself when 0).
   pure integer function body_holder(kinds, k) result(h)
      !> Kinds.
      type(particle_kind_type), intent(in) :: kinds(:)
      !> Kind.
      integer, intent(in) :: k
      h = kinds(k)%body_kind
      if (h == 0) h = k
   end function body_holder

   !> Support tables (anm_contact_body, `add_support_table`) for the contact bodies of the built
   !> kinds that have patch arrays and no table yet, built in parallel, once the run has made
   !> `attempts_per_table` attempts per such body since the last tables (`attempts`: the run's
   !> attempts so far), or at once with `now`. Kinds are built without tables: a table only
   !> shortens contact tests (their answers are the same), so when it is built changes the run's
   !> time, never its model.
   subroutine add_tables(self, kinds, attempts, now)
      !> Bookkeeping.
      class(kind_set_type), intent(inout) :: self
      !> Kinds.
      type(particle_kind_type), intent(inout) :: kinds(:)
      !> The run's attempts so far.
      integer(int64), intent(in) :: attempts
      !> Build the missing tables whatever the attempts.
      logical, intent(in), optional :: now
      integer, allocatable :: todo(:)
      integer :: k, i, n
      logical :: force
      force = .false.
      if (present(now)) force = now
      ! counted without allocating: this runs after every batch. Counted per built kind whose
      ! (shared) body has no table, as when each kind had its own body: the width levels of shells
      ! in mm spread a job's few particles over many kinds, whose tables do not pay (measured:
      ! 24 tables cost the shells-in-mm job about 0.8 s CPU, a fifth of it, and saved nothing)
      n = 0
      do k = 1, size(kinds)
         if (.not. self%built(k)) cycle
         if (needs_table(kinds(body_holder(kinds, k))%body)) n = n + 1
      end do
      if (n == 0) return
      if (.not. force .and. attempts - self%attempts_tabled < int(attempts_per_table, int64) * n) return
      ! the holders of the bodies (the others' bodies are empty)
      todo = pack([(k, k=1, size(kinds))], [(self%built(k) .and. needs_table(kinds(k)%body), k=1, size(kinds))])
      !$omp parallel do default(none) shared(kinds, todo) private(i) schedule(dynamic)
      do i = 1, size(todo)
         call add_support_table(kinds(todo(i))%body)
      end do
      !$omp end parallel do
      self%tables_built = self%tables_built + size(todo)
      self%attempts_tabled = attempts
   end subroutine add_tables

   !> Whether a body has patch arrays and no support table.
   pure logical function needs_table(body)
      type(contact_body_type), intent(in) :: body
      needs_table = allocated(body%node) .and. .not. allocated(body%supp)
   end function needs_table

   !> Build kinds(list) (`bases` or shells, as build_list): all here, or with an exchange, this
   !> process' share (items rank + 1, rank + 1 + nranks, ...) here and the others' received from
   !> them, one item (its cache payload) at a time. A process that fails to build returns its
   !> error, and the MPI program aborts the job.
   subroutine build_shared(ks, kinds, list, bases, error)
      type(kind_set_type), intent(inout) :: ks
      type(particle_kind_type), intent(inout) :: kinds(:)
      integer, intent(in) :: list(:)
      logical, intent(in) :: bases
      type(error_type), allocatable, intent(out) :: error
      type(byte_reader_type) :: r
      integer(int8), allocatable :: b(:)
      integer :: i, owner, nranks
      logical :: ok, shared
      character(len=80) :: msg
      shared = allocated(ks%exchange)
      if (shared) shared = ks%exchange%nranks > 1 .and. size(list) > 0
      if (.not. shared) then
         call build_list(ks, kinds, list, bases, error)
         return
      end if
      nranks = ks%exchange%nranks
      call build_list(ks, kinds, list(ks%exchange%rank + 1::nranks), bases, error)
      if (allocated(error)) return
      ks%exchange%built = ks%exchange%built + size(list(ks%exchange%rank + 1::nranks))
      do i = 1, size(list)
         owner = mod(i - 1, nranks)
         if (owner == ks%exchange%rank) then
            block
               type(byte_writer_type) :: item
               if (bases) then
                  call encode_base(ks, kinds(list(i)), item)
               else
                  call encode_shells(kinds(list(i)), item)
               end if
               b = item%bytes()
            end block
            call ks%exchange%broadcast(owner, b)
         else
            call ks%exchange%broadcast(owner, b)
            r = byte_reader_type(b=b)
            if (bases) then
               call decode_base(ks, kinds(list(i)), r, ok)
            else
               call decode_shells(ks, kinds(list(i)), r, ok)
            end if
            if (.not. ok) then
               write (msg, '(a,i0,a)') "kinds received from process ", owner, " are malformed"
               call fatal_error(error, trim(msg))
               return
            end if
            ks%exchange%received = ks%exchange%received + 1
         end if
         deallocate (b)
      end do
   end subroutine build_shared

   !> Build kinds(list) in parallel: their geometry and bare bodies (`bases`) or their shells.
   subroutine build_list(ks, kinds, list, bases, error)
      type(kind_set_type), intent(in) :: ks
      type(particle_kind_type), intent(inout) :: kinds(:)
      integer, intent(in) :: list(:)
      logical, intent(in) :: bases
      type(error_type), allocatable, intent(out) :: error
      type(error_type), allocatable :: errs(:)
      logical, allocatable :: failed(:)
      integer :: i
      if (size(list) == 0) return
      allocate (errs(size(list)), failed(size(list)))
      failed = .false.
      call build_originals(ks, kinds, list, failed, errs, bases)
      do i = 1, size(list)
         if (failed(i)) then
            call fatal_error(error, errs(i)%message, errs(i)%stat)
            return
         end if
      end do
   end subroutine build_list

   !> Cache key of a kind's base: order, N_ext, 1 (the patch arrays are kept), coefficients.
   function base_key(ks, kd) result(key)
      type(kind_set_type), intent(in) :: ks
      type(particle_kind_type), intent(in) :: kd
      type(byte_writer_type) :: w
      integer(int8), allocatable :: key(:)
      call key_start(ks%cache, "base", w)
      call w%put([kd%order, ks%p%n_ext, 1])
      call put_expansion(w, sh_truncate(ks%shapes(kd%shape), kd%order))
      key = w%bytes()
   end function base_key

   !> Cache key of a kind's shells: order, N_ext, the payload's version (2: no shell body), thicknesses
   !> (shape units), coefficients.
   function shells_key(ks, kd) result(key)
      type(kind_set_type), intent(in) :: ks
      type(particle_kind_type), intent(in) :: kd
      type(byte_writer_type) :: w
      integer(int8), allocatable :: key(:)
      real(wp), allocatable :: t(:)
      t = shell_thickness(ks%p, kd)
      call key_start(ks%cache, "shells", w)
      call w%put([kd%order, ks%p%n_ext, 2, size(t)])
      call w%put(t)
      call put_expansion(w, sh_truncate(ks%shapes(kd%shape), kd%order))
      key = w%bytes()
   end function shells_key

   !> A kind's geometry and bare body from the cache (hit) or nothing.
   subroutine load_base(ks, kd, hit)
      type(kind_set_type), intent(inout) :: ks
      type(particle_kind_type), intent(inout) :: kd
      logical, intent(out) :: hit
      type(byte_reader_type) :: r
      call ks%cache%load(base_key(ks, kd), r, hit)
      if (.not. hit) return
      call decode_base(ks, kd, r, hit)
      if (.not. hit) call reject(ks, hit)
   end subroutine load_base

   !> A kind's geometry and bare body from a payload (`encode_base`); `ok` false (and the body
   !> empty) when the payload is malformed.
   subroutine decode_base(ks, kd, r, ok)
      type(kind_set_type), intent(in) :: ks
      type(particle_kind_type), intent(inout) :: kd
      type(byte_reader_type), intent(inout) :: r
      logical, intent(out) :: ok
      type(contact_body_type) :: empty
      real(wp) :: g(3)
      call r%get(g)
      call get_body(r, kd%body)
      ok = r%done()
      if (.not. ok) then
         kd%body = empty
         return
      end if
      kd%width = g(1)
      kd%length = g(2)
      kd%volume = g(3)
      kd%body%shape = sh_truncate(ks%shapes(kd%shape), kd%order)
      call body_radii(kd)
   end subroutine decode_base

   !> Store a kind's geometry and bare body.
   subroutine store_base(ks, kd)
      type(kind_set_type), intent(inout) :: ks
      type(particle_kind_type), intent(in) :: kd
      type(byte_writer_type) :: w
      call encode_base(ks, kd, w)
      call ks%cache%store(base_key(ks, kd), w%bytes())
   end subroutine store_base

   !> The payload of a kind's geometry and bare body.
   subroutine encode_base(ks, kd, w)
      type(kind_set_type), intent(in) :: ks
      type(particle_kind_type), intent(in) :: kd
      type(byte_writer_type), intent(inout) :: w
      call w%put([kd%width, kd%length, kd%volume])
      call put_body(w, kd%body, .true.)
   end subroutine encode_base

   !> A kind's shells from the cache (hit) or nothing; its base is in place.
   subroutine load_shells(ks, kd, hit)
      type(kind_set_type), intent(inout) :: ks
      type(particle_kind_type), intent(inout) :: kd
      logical, intent(out) :: hit
      type(byte_reader_type) :: r
      call ks%cache%load(shells_key(ks, kd), r, hit)
      if (.not. hit) return
      call decode_shells(ks, kd, r, hit)
      if (.not. hit) call reject(ks, hit)
   end subroutine load_shells

   !> A kind's shells from a payload (`encode_shells`); its base is in place. `ok` false (and no
   !> shells) when the payload is malformed or holds another number of layers.
   subroutine decode_shells(ks, kd, r, ok)
      type(kind_set_type), intent(in) :: ks
      type(particle_kind_type), intent(inout) :: kd
      type(byte_reader_type), intent(inout) :: r
      logical, intent(out) :: ok
      type(sh_expansion_type), allocatable :: layers(:)
      real(wp), allocatable :: vol(:)
      integer :: n, k
      ok = .false.
      call r%get(n)
      if (n /= ks%p%nlayer) return
      allocate (layers(n), vol(n))
      do k = 1, n
         call get_expansion(r, layers(k))
      end do
      call r%get(vol)
      if (.not. r%done()) return
      ok = .true.
      call move_alloc(layers, kd%layers)
      call move_alloc(vol, kd%layer_volume)
   end subroutine decode_shells

   !> Store a kind's shells.
   subroutine store_shells(ks, kd)
      type(kind_set_type), intent(inout) :: ks
      type(particle_kind_type), intent(in) :: kd
      type(byte_writer_type) :: w
      call encode_shells(kd, w)
      call ks%cache%store(shells_key(ks, kd), w%bytes())
   end subroutine store_shells

   !> The payload of a kind's shells.
   subroutine encode_shells(kd, w)
      type(particle_kind_type), intent(in) :: kd
      type(byte_writer_type), intent(inout) :: w
      integer :: k
      call w%put(size(kd%layers))
      do k = 1, size(kd%layers)
         call put_expansion(w, kd%layers(k))
      end do
      call w%put(kd%layer_volume)
   end subroutine encode_shells

   !> A cache entry that held the right key but a malformed payload: counted as rejected.
   subroutine reject(ks, hit)
      type(kind_set_type), intent(inout) :: ks
      logical, intent(out) :: hit
      hit = .false.
      ks%cache%hits = ks%cache%hits - 1
      ks%cache%rejected = ks%cache%rejected + 1
   end subroutine reject

   !> A kind's geometry from its base (another width level of its shape and order), whose bare
   !> body (held by kind `holder`: `body`) it shares.
   subroutine copy_base(from, kd, holder, body)
      type(particle_kind_type), intent(in) :: from
      type(particle_kind_type), intent(inout) :: kd
      integer, intent(in) :: holder
      type(contact_body_type), intent(in) :: body
      kd%width = from%width
      kd%length = from%length
      kd%volume = from%volume
      kd%body_kind = holder
      kd%r_out = body%r_max
      kd%r_in_query = body%r_min
      kd%r_in_parked = body%r_min
   end subroutine copy_base

   !> A kind equal to an earlier one (`same`): everything but the bare body, which it shares
   !> (held by kind `holder`), and the layers, which `build_layers` copies when asked for.
   subroutine copy_kind(from, kd, holder)
      type(particle_kind_type), intent(in) :: from
      type(particle_kind_type), intent(inout) :: kd
      integer, intent(in) :: holder
      type(contact_body_type) :: empty
      kd%shape = from%shape
      kd%sieve = from%sieve
      kd%order = from%order
      kd%level = from%level
      kd%width = from%width
      kd%length = from%length
      kd%volume = from%volume
      kd%body = empty
      kd%body_kind = holder
      kd%gap = from%gap
      kd%r_out = from%r_out
      kd%r_in_query = from%r_in_query
      kd%r_in_parked = from%r_in_parked
   end subroutine copy_kind

   !> Build kinds(todo) in parallel (each kind by one thread; failures in failed/errs): their
   !> geometry and bare body (`bases`) or, with these in place, their shells.
   subroutine build_originals(ks, kinds, todo, failed, errs, bases)
      type(kind_set_type), intent(in) :: ks
      type(particle_kind_type), intent(inout) :: kinds(:)
      integer, intent(in) :: todo(:)
      logical, intent(inout) :: failed(:)
      type(error_type), intent(inout) :: errs(:)
      logical, intent(in) :: bases
      integer :: i
      !$omp parallel do default(none) shared(ks, kinds, todo, failed, errs, bases) private(i) schedule(dynamic)
      do i = 1, size(todo)
         block
            type(error_type), allocatable :: err
            associate (kd => kinds(todo(i)))
               if (bases) then
                  call prepare_base(ks%p, ks%shapes(kd%shape), kd, err)
               else
                  call prepare_shells(ks%p, ks%shapes(kd%shape), ks%names(kd%shape)%s, kd, err)
               end if
            end associate
            if (allocated(err)) then
               failed(i) = .true.
               errs(i) = err
            end if
         end block
      end do
      !$omp end parallel do
   end subroutine build_originals

   !> Width of a kind's width level (shells in mm).
   pure real(wp) function level_width(p, kd) result(w)
      type(kind_params_type), intent(in) :: p
      type(particle_kind_type), intent(in) :: kd
      w = p%min_width(kd%sieve) + (kd%level - 0.5_wp) * (p%max_width(kd%sieve) - p%min_width(kd%sieve)) &
          / width_levels
   end function level_width

   !> Geometry and bare contact body of one kind (shared by its width levels).
   subroutine prepare_base(p, shape, kd, error)
      type(kind_params_type), intent(in) :: p
      type(sh_expansion_type), intent(in) :: shape
      type(particle_kind_type), intent(inout) :: kd
      type(error_type), allocatable, intent(out) :: error
      type(shape_geometry_type) :: g
      type(sh_expansion_type) :: s
      s = sh_truncate(shape, kd%order)
      ! the body first: its certified radius bounds speed up the dimensions' chord marches
      call new_contact_body(kd%body, s, error, next=p%n_ext, table=.false.)
      if (allocated(error)) return
      call compute_geometry(s, g, bound=radial_bound(kd%body, 16))
      kd%width = g%width
      kd%length = g%length
      kd%volume = g%volume
      call body_radii(kd)
   end subroutine prepare_base

   !> The overlap radii (without shells) of a kind holding its bare body.
   subroutine body_radii(kd)
      type(particle_kind_type), intent(inout) :: kd
      kd%r_out = kd%body%r_max
      kd%r_in_query = kd%body%r_min
      kd%r_in_parked = kd%body%r_min
   end subroutine body_radii

   !> Thicknesses of a kind's layers in shape units (with shells in mm at its width level).
   function shell_thickness(p, kd) result(t)
      type(kind_params_type), intent(in) :: p
      type(particle_kind_type), intent(in) :: kd
      real(wp), allocatable :: t(:)
      real(wp) :: w, sc
      sc = 1.0_wp
      if (p%unit == thickness_unit%mm) then
         w = level_width(p, kd)
         sc = w / kd%width
      end if
      t = thickness_to_shape_units(p%thickness, p%unit, kd%length, sc)
   end function shell_thickness

   !> Shells of one kind whose geometry and bare body are in place.
   subroutine prepare_shells(p, shape, name, kd, error)
      type(kind_params_type), intent(in) :: p
      type(sh_expansion_type), intent(in) :: shape
      character(len=*), intent(in) :: name
      type(particle_kind_type), intent(inout) :: kd
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: s
      type(shell_report_type), allocatable :: reports(:)
      real(wp), allocatable :: t(:)
      integer :: k
      if (p%nlayer == 0) return
      s = sh_truncate(shape, kd%order)
      t = shell_thickness(p, kd)
      call build_layers(s, t, kd%layers, reports, error, label=name)
      if (allocated(error)) then
         error%message = p%file//": &shells: "//error%message
         return
      end if
      allocate (kd%layer_volume(size(t)))
      do k = 1, size(t)
         kd%layer_volume(k) = reports(k)%outer_volume
      end do
   end subroutine prepare_shells

   !> The gap and overlap radii of a kind with shells (its bare body: `body`). Overlapping shells
   !> do not take part in the parking; the others are a gap kept around the bare body by the
   !> distance test (no contact body of their own).
   subroutine shell_radii(p, kd, body)
      type(kind_params_type), intent(in) :: p
      type(particle_kind_type), intent(inout) :: kd
      type(contact_body_type), intent(in) :: body
      real(wp), allocatable :: t(:)
      if (p%nlayer == 0 .or. p%mode == shell_mode%overlap) return
      t = shell_thickness(p, kd)
      kd%gap = maxval(t)
      kd%r_out = body%r_max + kd%gap
      kd%r_in_query = body%r_min + kd%gap
      if (p%mode == shell_mode%exclude) kd%r_in_parked = body%r_min + kd%gap
   end subroutine shell_radii

   !> Memory held by a kind (bytes): its bare body (when it holds one: `body_kind`), layers and
   !> the scalars.
   pure integer(int64) function kind_bytes(kd) result(n)
      !> Kind.
      type(particle_kind_type), intent(in) :: kd
      integer :: k
      n = storage_size(kd) / 8 + body_bytes(kd%body)
      if (allocated(kd%layers)) then
         do k = 1, size(kd%layers)
            n = n + expansion_bytes(kd%layers(k))
         end do
         n = n + 8 * size(kd%layer_volume)
      end if
   end function kind_bytes

   !> Memory held by a contact body (bytes): its arrays and expansion.
   pure integer(int64) function body_bytes(b) result(n)
      !> Body.
      type(contact_body_type), intent(in) :: b
      n = storage_size(b) / 8 + expansion_bytes(b%shape) - storage_size(b%shape) / 8
      if (allocated(b%node)) n = n + 8_int64 * (size(b%dir) + size(b%cosa) + size(b%sina) + size(b%rlo) + size(b%rhi) &
                                               + size(b%ball) + size(b%brad) + size(b%row_ct) + size(b%row_st) &
                                               + size(b%row_cosa) + size(b%row_sina) + size(b%col_cp) + size(b%col_sp) &
                                               + size(b%node)) + 4_int64 * (size(b%dlo) + size(b%dhi))
      if (allocated(b%supp)) n = n + 4_int64 * size(b%supp)
   end function body_bytes

   !> Memory held by an expansion (bytes): coefficients and Legendre table.
   pure integer(int64) function expansion_bytes(e) result(n)
      type(sh_expansion_type), intent(in) :: e
      n = storage_size(e) / 8
      if (allocated(e%a)) n = n + 8_int64 * (size(e%a) + size(e%b))
      if (allocated(e%table%ca)) n = n + 8_int64 * (size(e%table%ca) + size(e%table%cb) + size(e%table%sect) &
                                                    + size(e%table%dq)) + 4_int64 * size(e%table%idx)
   end function expansion_bytes

   !> The on-disk cache folder from the environment: ANM_CACHE ('' when unset; 'off' disables).
   function cache_environment() result(dir)
      character(len=:), allocatable :: dir
      integer :: n, stat
      call get_environment_variable("ANM_CACHE", length=n, status=stat)
      if (stat /= 0 .or. n == 0) then
         dir = ""
         return
      end if
      allocate (character(len=n) :: dir)
      call get_environment_variable("ANM_CACHE", dir)
   end function cache_environment
end module anm_parking_kinds
